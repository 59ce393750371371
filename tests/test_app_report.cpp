// mcms report (and --html of demo and fov-map) in a real browser: the HTML page of `mcms demo`,
// and the first screen of every command's output (visible without scrolling at 1366 x 768),
// and of `mcms fov-map` opens in
// headless Chromium (Debian's chromium, scripts/setup.sh installs it) with no console
// message but the page's own "N of N figures rendered", every figure decoded by the
// browser, and a screenshot that is not blank (kept as a test artefact in
// build/test-artifacts/report-demo.png). The check is shown to fail on a figure the browser
// cannot decode. Bad input on the command line is refused with nothing written.
// Skipped, with the reason, when chromium is not installed ($MCMS_CHROMIUM overrides the
// path).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/cli_runner.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

using test::CliRun;

CliRun Shell(const std::string& cmd, const fs::path& scratch) { return test::Shell(scratch, cmd); }
CliRun Mcms(const std::string& args, const fs::path& scratch) { return test::Mcms(scratch, args); }

std::string Chromium() {
  if (const char* env = std::getenv("MCMS_CHROMIUM")) return env;
  return "/usr/bin/chromium";
}

size_t Count(const std::string& s, const std::string& needle) {
  size_t n = 0;
  for (size_t p = s.find(needle); p != std::string::npos; p = s.find(needle, p + 1)) ++n;
  return n;
}

struct BrowserResult {
  int figures = -1, rendered = -1;          // from the page's script, read back from the DOM
  int headline_bottom = -1;                 // where the first screen's headline ends (px, at 1366 x 768)
  std::string answer_status;                // its class: ok, findings, failed, empty
  std::vector<std::string> console;         // every console message of the page
};

// Opens `page` in headless Chromium: the DOM after load (what the page's script found) and
// the console messages; with `screenshot`, also a 1280 x 4000 screenshot.
BrowserResult OpenInBrowser(const fs::path& page, const fs::path& scratch, const fs::path& screenshot = {}) {
  const std::string common = "timeout 120 " + Chromium() +
                             " --headless --no-sandbox --disable-gpu --no-first-run --hide-scrollbars"
                             " --enable-logging=stderr --v=0 --virtual-time-budget=5000 --user-data-dir=" +
                             (scratch / "chromium-profile").string();
  const std::string url = "file://" + fs::absolute(page).string();
  BrowserResult r;
  // The DOM at a laptop's 1366 x 768: what the page's script measured there.
  const CliRun dom = Shell(common + " --window-size=1366,768 --dump-dom " + url, scratch);
  EXPECT_EQ(dom.code, 0) << dom.err;
  std::smatch m;
  if (std::regex_search(dom.out, m, std::regex("<body data-figures=\"([0-9]+)\" data-figures-rendered=\"([0-9]+)\"")))
    r.figures = std::stoi(m[1]), r.rendered = std::stoi(m[2]);
  if (std::regex_search(dom.out, m, std::regex("data-headline-bottom=\"([0-9]+)\"")))
    r.headline_bottom = std::stoi(m[1]);
  if (std::regex_search(dom.out, m, std::regex("data-answer-status=\"([a-z]+)\""))) r.answer_status = m[1];
  // Chromium logs every console message of the page (log, warning, error, uncaught
  // exception, refused resource) as one INFO:CONSOLE line on stderr.
  std::istringstream lines(dom.err);
  for (std::string line; std::getline(lines, line);)
    if (line.find(":CONSOLE") != std::string::npos) r.console.push_back(line);
  if (!screenshot.empty()) {
    // The first screen as a laptop shows it, kept beside the whole page.
    const fs::path first = screenshot.parent_path() / ("first-screen-" + screenshot.filename().string());
    fs::remove(first);
    const CliRun first_shot = Shell(common + " --window-size=1366,768 --screenshot=" + first.string() + " " + url, scratch);
    EXPECT_EQ(first_shot.code, 0) << first_shot.err;
    EXPECT_TRUE(fs::exists(first));
    fs::remove(screenshot);
    const CliRun shot = Shell(common + " --window-size=1280,4000 --screenshot=" + screenshot.string() + " " + url, scratch);
    EXPECT_EQ(shot.code, 0) << shot.err;
  }
  return r;
}

// Every figure of the page rendered and the only console message is the page's own.
void ExpectCleanPage(const fs::path& page, const fs::path& scratch, size_t min_figures, const fs::path& screenshot = {}) {
  const std::string html = test::ReadAll(page);
  const int embedded = static_cast<int>(Count(html, "<img class=\"figure\""));
  EXPECT_GE(embedded, static_cast<int>(min_figures));
  const BrowserResult b = OpenInBrowser(page, scratch, screenshot);
  EXPECT_EQ(b.figures, embedded);
  EXPECT_EQ(b.rendered, embedded);
  ASSERT_EQ(b.console.size(), 1u) << "console messages:\n" << [&] {
    std::string all;
    for (const auto& l : b.console) all += l + "\n";
    return all;
  }();
  const std::string expected = "\"mcms report: " + std::to_string(embedded) + " of " + std::to_string(embedded) +
                               " figures rendered\"";
  EXPECT_NE(b.console[0].find(expected), std::string::npos) << b.console[0];
  if (screenshot.empty()) return;
  // The screenshot: the page's size, and not blank (text, plots and tables on white).
  const cv::Mat img = cv::imread(screenshot.string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(img.empty()) << "no screenshot at " << screenshot;
  EXPECT_EQ(img.cols, 1280);
  EXPECT_EQ(img.rows, 4000);
  const double inked = static_cast<double>(cv::countNonZero(img < 200)) / static_cast<double>(img.total());
  EXPECT_GT(inked, 0.005) << "the screenshot is (nearly) blank";
  cv::Scalar mean, sd;
  cv::meanStdDev(img, mean, sd);
  EXPECT_GT(sd[0], 10.0);
  std::printf("screenshot of %s: %s (%.1f %% of the pixels inked)\n", page.filename().c_str(), screenshot.c_str(), 100 * inked);
}

#define REQUIRE_CHROMIUM()                                                                     \
  if (::access(Chromium().c_str(), X_OK) != 0)                                                 \
  GTEST_SKIP() << "skipped: chromium not found at " << Chromium()                              \
               << " (Debian package chromium; scripts/setup.sh installs it; $MCMS_CHROMIUM overrides)"

TEST(ReportCli, DemoReportOpensInHeadlessChromiumWithEveryFigure) {
  REQUIRE_CHROMIUM();
  const fs::path s = test::ScratchDir("report_demo");
  // `mcms demo` writes the page by default (issue 26), as `mcms report DIR` does, and says
  // where it is.
  const CliRun demo = Mcms("demo --quiet --points 4 -o " + (s / "demo").string(), s);
  ASSERT_EQ(demo.code, 0) << demo.err;
  const fs::path page = s / "demo" / "report.html";
  EXPECT_NE(demo.out.find("report: " + page.string()), std::string::npos) << demo.out;
  ASSERT_TRUE(fs::exists(page));
  const std::string from_demo = test::ReadAll(page);
  const CliRun rep = Mcms("report " + (s / "demo").string(), s);
  ASSERT_EQ(rep.code, 0) << rep.err;
  EXPECT_NE(rep.out.find("the output of mcms demo"), std::string::npos) << rep.out;
  EXPECT_EQ(test::ReadAll(page), from_demo);
  // Every SVG the demo wrote is on the page, with its summary and tables.
  size_t svgs = 0;
  for (const auto& e : fs::directory_iterator(s / "demo")) svgs += e.path().extension() == ".svg";
  EXPECT_GE(svgs, 4u);  // the per-point errors and the ISO 9283 plots
  const std::string html = test::ReadAll(page);
  // ... and the per-frame plots of its tracker_poses.csv: status, position, predicted sigma,
  // reprojection RMS.
  EXPECT_EQ(Count(html, "<img class=\"figure\""), svgs + 4);
  EXPECT_NE(html.find("tracker_poses.csv: status per frame"), std::string::npos);
  for (const char* needle : {"summary.txt", "point_errors.csv", "iso9283_summary.txt", "fusion_setup.yaml"})
    EXPECT_NE(html.find(needle), std::string::npos) << needle;
  const fs::path artefacts = fs::path(MCMS_BINARY_DIR) / "test-artifacts";
  fs::create_directories(artefacts);
  ExpectCleanPage(page, s, svgs + 4, artefacts / "report-demo.png");
  const BrowserResult b = OpenInBrowser(page, s);
  EXPECT_EQ(b.answer_status, "ok");
  EXPECT_GT(b.headline_bottom, 100);
  EXPECT_LE(b.headline_bottom, 768) << "the demo's headline is not visible without scrolling at 1366 x 768";
}

// Issue 26: the output of every command that writes a folder leads with its own first
// screen, visible without scrolling at 1366 x 768 (the bottom of its lead and first table,
// measured by the browser), with no console error; a screenshot of each first screen is kept
// in build/test-artifacts/first-screen-<command>.png.
TEST(ReportCli, EveryCommandsFirstScreenIsVisibleWithoutScrolling) {
  REQUIRE_CHROMIUM();
  const fs::path s = test::ScratchDir("report_first_screens");
  const std::string d = s.string();
  for (const std::string& cmd :
       {"render --quiet --frames 40 -o " + d + "/rec", "track --quiet " + d + "/rec",
        "audit cameras --quiet " + d + "/rec -o " + d + "/audit",
        "fov-map --quiet --grid=-0.5:0.5:5,-0.4:0.4:4,0:1:3 -o " + d + "/fov",
        "iso9283 --simulate --cycles 3 -o " + d + "/iso/iso9283.csv"}) {
    if (cmd.rfind("iso9283", 0) == 0) fs::create_directories(s / "iso");
    const CliRun r = Mcms(cmd, s);
    ASSERT_EQ(r.code, 0) << cmd << "\n" << r.err;
  }
  fs::create_directories(s / "empty");
  const fs::path artefacts = fs::path(MCMS_BINARY_DIR) / "test-artifacts";
  fs::create_directories(artefacts);
  struct Case {
    std::string folder, kind, status, lead;
  };
  for (const Case& c : std::vector<Case>{{"rec", "track", "ok", "40 frames: "},
                                         {"audit", "audit", "", "audit"},
                                         {"fov", "fov-map", "ok", "The rig measures with sigma_d"},
                                         {"iso", "iso9283", "ok", "ISO 9283 pose accuracy AP and repeatability RP"},
                                         {"empty", "mcms output", "empty", "Nothing to report"}}) {
    SCOPED_TRACE(c.folder);
    const fs::path page = s / (c.folder + ".html");
    const CliRun rep = Mcms("report " + (s / c.folder).string() + " -o " + page.string(), s);
    ASSERT_EQ(rep.code, 0) << rep.err;
    EXPECT_NE(rep.out.find(c.kind == "mcms output" ? "an mcms command" : "the output of mcms " + c.kind),
              std::string::npos) << rep.out;
    EXPECT_NE(test::ReadAll(page).find(c.lead), std::string::npos);
    const std::string name = c.kind == "mcms output" ? c.folder : c.kind;
    const fs::path shot = artefacts / ("first-screen-" + name + ".png");
    fs::remove(shot);
    const BrowserResult b = OpenInBrowser(page, s);
    if (!c.status.empty()) {
      EXPECT_EQ(b.answer_status, c.status);
    }
    EXPECT_GT(b.headline_bottom, 100);
    EXPECT_LE(b.headline_bottom, 768) << "the headline is not visible without scrolling at 1366 x 768";
    for (const auto& l : b.console) EXPECT_EQ(l.find("error"), std::string::npos) << l;
    const CliRun pic = Shell("timeout 120 " + Chromium() + " --headless --no-sandbox --disable-gpu --no-first-run " +
                                 "--hide-scrollbars --user-data-dir=" + (s / "chromium-profile").string() +
                                 " --window-size=1366,768 --screenshot=" + shot.string() + " file://" + page.string(),
                             s);
    EXPECT_EQ(pic.code, 0) << pic.err;
    EXPECT_FALSE(cv::imread(shot.string()).empty()) << shot;
  }
  // An empty folder's page says so on the command line too.
  const CliRun empty = Mcms("report " + (s / "empty").string() + " -o " + (s / "e.html").string(), s);
  EXPECT_NE(empty.err.find("holds no result; its first screen says so"), std::string::npos) << empty.err;
}

TEST(ReportCli, FovMapReportOpensInHeadlessChromium) {
  REQUIRE_CHROMIUM();
  const fs::path s = test::ScratchDir("report_fovmap");
  const CliRun map = Mcms("fov-map --quiet --html --grid=-0.5:0.5:5,-0.4:0.4:4,0:1:3 -o " + (s / "map").string(), s);
  ASSERT_EQ(map.code, 0) << map.err;
  EXPECT_TRUE(fs::exists(s / "map" / "report.html"));
  const CliRun rep = Mcms("report " + (s / "map").string() + " -o " + (s / "map.html").string(), s);
  ASSERT_EQ(rep.code, 0) << rep.err;
  EXPECT_NE(rep.out.find("the output of mcms fov-map"), std::string::npos) << rep.out;
  ExpectCleanPage(s / "map.html", s, 4);  // three heat maps and sigma against distance
}

// The browser check fails on a figure the browser cannot decode: malformed XML that still
// looks like an SVG document to the page builder.
TEST(ReportCli, BrowserCheckCatchesAFigureThatDoesNotRender) {
  REQUIRE_CHROMIUM();
  const fs::path s = test::ScratchDir("report_broken_figure");
  fs::create_directories(s / "run");
  std::ofstream(s / "run" / "bad.svg") << "<svg xmlns='http://www.w3.org/2000/svg' width='10' height='10'><rect></svg>";
  std::ofstream(s / "run" / "summary.txt") << "a run\n";
  ASSERT_EQ(Mcms("report " + (s / "run").string(), s).code, 0);
  const BrowserResult b = OpenInBrowser(s / "run" / "report.html", s);
  EXPECT_EQ(b.figures, 1);
  EXPECT_EQ(b.rendered, 0);
  ASSERT_EQ(b.console.size(), 1u);
  EXPECT_NE(b.console[0].find("figures not rendered: bad.svg"), std::string::npos) << b.console[0];
}

TEST(ReportCli, BadInputIsRefusedWithNothingWritten) {
  const fs::path s = test::ScratchDir("report_bad");
  CliRun r = Mcms("report " + (s / "missing").string(), s);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("missing does not exist"), std::string::npos) << r.err;
  std::ofstream(s / "file.txt") << "x\n";
  r = Mcms("report " + (s / "file.txt").string(), s);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("is not a folder"), std::string::npos) << r.err;
  fs::create_directories(s / "run" / "x.html");
  std::ofstream(s / "run" / "summary.txt") << "ok\n";
  r = Mcms("report " + (s / "run").string() + " -o " + (s / "run" / "x.html").string(), s);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("is a folder"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace mcms
