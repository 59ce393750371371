// The HTML report (jobs/html_report.h) and the readability of the SVG plots it embeds
// (core/svg_plot.h): every figure of the folder is on the page byte for byte, tables are
// shown or summarised, a tracker pose CSV gets its per-frame plots (error with the predicted
// band, NEES with its chi-square band), the page references nothing outside itself, bad
// files are named on the page, and a bad folder or output is refused with nothing written.
// Log axes are labelled in real units and the legend never overlaps the plot area.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "jobs/html_report.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

std::string Base64Decode(const std::string& in) {
  auto val = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  int bits = 0, acc = 0;
  for (char c : in) {
    const int v = val(c);
    if (v < 0) break;
    acc = (acc << 6) | v;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((acc >> bits) & 0xff);
    }
  }
  return out;
}

// The decoded SVG documents embedded as figures, in page order.
std::vector<std::string> EmbeddedFigures(const std::string& html) {
  std::vector<std::string> out;
  const std::string key = "src=\"data:image/svg+xml;base64,";
  for (size_t p = html.find(key); p != std::string::npos; p = html.find(key, p + 1)) {
    const size_t b = p + key.size(), e = html.find('"', b);
    out.push_back(Base64Decode(html.substr(b, e - b)));
  }
  return out;
}

size_t Count(const std::string& s, const std::string& needle) {
  size_t n = 0;
  for (size_t p = s.find(needle); p != std::string::npos; p = s.find(needle, p + 1)) ++n;
  return n;
}

Plot SamplePlot() {
  Plot p{"Errors <per> point & more", "distance (m)", "error (mm)", {}};
  PlotSeries a{"measured", {0.5, 1.0, 1.5, 2.0}, {0.004, 0.02, 0.3, 0.9}, "#d62728", true};
  PlotSeries b{"predicted", {0.5, 1.0, 1.5, 2.0}, {0.005, 0.03, 0.2, 0.8}, "#1f77b4", false};
  p.series = {a, b};
  return p;
}

TEST(HtmlReport, EmbedsEveryFigureAndShowsTablesReportsAndInputs) {
  const fs::path d = test::ScratchDir("html_report_mixed");
  SamplePlot().WriteSvg(d / "errors.svg");
  HeatMap h{"map", "x (m)", "y (m)", "sigma (mm)", {0, 1}, {0, 1}, {1, 2, 3, NAN}, {}, {}, false, 2.5};
  h.WriteSvg(d / "heatmap.svg");
  test::WriteText(d / "summary.txt", "mean error 0.02 mm < 0.05 mm & fine\n");
  test::WriteText(d / "setup.yaml", "rig: {cameras: 4}\n");
  std::string long_text;
  for (int i = 0; i < 200; ++i) long_text += "line " + std::to_string(i) + "\n";
  test::WriteText(d / "region.txt", long_text);
  test::WriteText(d / "small.csv", "point,err_mm\n1,0.5\n2,0.25\n");
  std::string big = "# a comment line\ncondition,value\n";
  for (int i = 0; i < 100; ++i) big += std::string(i % 3 ? "\"a, b\"" : "c") + "," + std::to_string(i) + "\n";
  test::WriteText(d / "big.csv", big);
  test::WriteText(d / "broken.svg", "<html>not a figure</html>");
  test::WriteText(d / "ragged.csv", "a,b\n1,2\n3\n");
  test::WriteText(d / "picture.png", "\x89PNG");
  fs::create_directories(d / "images" / "cam0");
  test::WriteText(d / "images" / "cam0" / "0.png", "x");
  test::WriteText(d / "out.csv.partial-123", "half");

  HtmlReportContents c;
  const std::string html = BuildHtmlReport({d, "", 25, 100000}, &c);
  EXPECT_EQ(c.figures, 2u);
  EXPECT_EQ(c.tables, 2u);  // small and big; ragged is named with its problem
  EXPECT_EQ(c.texts, 2u);
  // summary.txt before the other reports; a long report shows 60 lines, the rest collapsed.
  EXPECT_LT(html.find("<h3>summary.txt</h3>"), html.find("<h3>region.txt</h3>"));
  EXPECT_NE(html.find("line 59\n</pre>\n<details><summary>140 more lines</summary><pre>line 60\n"), std::string::npos);
  EXPECT_EQ(c.inputs, 1u);
  // The figures are the files, byte for byte.
  const auto figs = EmbeddedFigures(html);
  ASSERT_EQ(figs.size(), 2u);
  EXPECT_EQ(figs[0], test::ReadAll(d / "errors.svg"));
  EXPECT_EQ(figs[1], test::ReadAll(d / "heatmap.svg"));
  // Text is escaped; tables shown or summarised.
  EXPECT_NE(html.find("mean error 0.02 mm &lt; 0.05 mm &amp; fine"), std::string::npos);
  EXPECT_NE(html.find("<td>0.25</td>"), std::string::npos);
  EXPECT_NE(html.find("100 rows, 2 columns"), std::string::npos);
  EXPECT_NE(html.find("a, b (66)"), std::string::npos);  // a quoted cell with a comma, counted
  EXPECT_NE(html.find("# a comment line"), std::string::npos);
  // A long table: summarised, the whole of it sortable in a folded section; beyond 2,000
  // rows its first and last rows.
  EXPECT_NE(html.find("<details><summary>all 100 rows (a click on a column's header sorts by it)</summary>"),
            std::string::npos);
  EXPECT_NE(html.find("<tr><td>c</td><td>99</td></tr>"), std::string::npos);
  EXPECT_EQ(Count(html, "<table class=\"sortable\">"), 2u);
  std::string huge = "i\n";
  for (int i = 0; i < 2500; ++i) huge += std::to_string(i) + "\n";
  test::WriteText(d / "huge.csv", huge);
  const std::string with_huge = BuildHtmlReport({d, "", 25, 100000});
  EXPECT_NE(with_huge.find("... 2476 rows ..."), std::string::npos);
  fs::remove(d / "huge.csv");
  EXPECT_NE(html.find("rig: {cameras: 4}"), std::string::npos);
  // Bad files are named on the page, with the problem.
  EXPECT_NE(html.find("broken.svg: not an SVG document"), std::string::npos);
  EXPECT_NE(html.find("ragged.csv: not shown as a table: line 3: expected 2 columns as in the header, found 1"), std::string::npos);
  EXPECT_NE(html.find("images/ (1 files, not embedded)"), std::string::npos);
  EXPECT_EQ(html.find("partial-123"), std::string::npos);
  // Nothing outside the page: no URL but the SVG namespace inside the (encoded) figures.
  for (const char* ext : {"src=\"http", "href=\"http", "url(http", "src=\"file", "<link", "@import"})
    EXPECT_EQ(html.find(ext), std::string::npos) << ext;
  EXPECT_EQ(Count(html, "<script>"), 1u);
  EXPECT_EQ(c.kind, "mcms output");
}

// Issue 26: the demo's page leads with the answer: the headline table of each sensor's and
// each fused result's three-sigma error and reduction, before the reports and figures.
TEST(HtmlReport, DemoPageLeadsWithTheAnswer) {
  const fs::path d = test::ScratchDir("html_report_demo_headline");
  test::WriteText(
      d / "summary.txt",
      "Tracker (rig frame, every frame):\nframes: 8 (ok 8, degraded 0, lost 0)\n\n"
      "Flange pose at the 2 points (robot base frame), each sensor alone and fused:\n"
      "method   points   pos RMS mm  pos 3sig mm  reduction tilt RMS deg  yaw RMS deg  mean NEES 95% band\n"
      "camera        2       0.0077       0.0170       0.0%      0.00473      0.00210       5.77 [5.25, 6.80]\n"
      "robot         2       0.0732       0.1211    -611.1%      0.00687      0.00748       4.57 [5.25, 6.80]\n"
      "MOIFA         2       0.0073       0.0163       4.2%      0.00073      0.00198       5.61 [5.25, 6.80]\n"
      "KF            2       0.0073       0.0163       4.2%      0.00073      0.00198       5.69 [5.25, 6.80]\n"
      "inclinometer alone: tilt reading RMS error 0.00073 deg (dwell mean); yaw: not observable\n"
      "KF mean NIS per dof: camera 1.005, robot 0.002, inclinometer 0.999 (1 when consistent)\n"
      "\nAgainst the paper's lab experiment (Tables 3-4):\n"
      "  three-sigma position error, mm: camera 0.017 (paper 3.940), robot 0.121 (paper 3.379)\n"
      "  MOIFA reduction   4.2 % +- 1.8 % (paper 38.2 %): NOT within 2 sd\n");
  test::WriteText(d / "point_errors.csv", "point,camera_pos_err_mm\n0,0.1\n");
  test::WriteText(d / "fused_poses.csv", "frame,time_s\n0,1\n");
  WriteHtmlReport({d}, d / "report.html");
  const std::string html = test::ReadAll(d / "report.html");
  const size_t answer = html.find("<h2>The answer</h2>");
  ASSERT_NE(answer, std::string::npos) << html.substr(0, 2000);
  EXPECT_LT(answer, html.find("<h3>summary.txt</h3>"));
  EXPECT_NE(html.find("<tr class=\"fused\"><td>MOIFA</td><td>0.0163</td><td>0.0073</td><td>4.2%</td>"),
            std::string::npos);
  EXPECT_NE(html.find("<tr><td>robot</td><td>0.1211</td>"), std::string::npos);
  EXPECT_EQ(html.find("<td>per</td>"), std::string::npos) << "the NIS line is not a row";
  const size_t table_end = html.find("</table>", answer);
  size_t rows = 0;
  for (size_t at = html.find("<tr", answer); at < table_end; at = html.find("<tr", at + 1)) ++rows;
  EXPECT_EQ(rows, 5u) << "a header and the four methods";
  EXPECT_NE(html.find("<li>MOIFA reduction   4.2 % +- 1.8 % (paper 38.2 %): NOT within 2 sd</li>"), std::string::npos);
  // Another command's folder gets no demo headline: its first screen says no result was
  // recognised.
  const fs::path other = test::ScratchDir("html_report_no_headline");
  test::WriteText(other / "summary.txt", "ok\n");
  WriteHtmlReport({other}, other / "report.html");
  const std::string other_html = test::ReadAll(other / "report.html");
  EXPECT_EQ(other_html.find("Flange pose error"), std::string::npos);
  EXPECT_NE(other_html.find("No known command&#39;s result was recognised"), std::string::npos);
}

TEST(HtmlReport, TrackerPosesGetPerFramePlotsWithPredictedBands) {
  const fs::path d = test::ScratchDir("html_report_track");
  std::string csv =
      "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz,balls,rms_px,cov_px_px,cov_py_py,cov_pz_pz,"
      "err_x_mm,err_y_mm,err_z_mm,err_rot_mdeg,nees\n";
  for (int i = 0; i < 40; ++i) {
    const bool lost = i % 10 == 7;
    char row[400];
    if (lost)
      std::snprintf(row, sizeof(row), "%d,%.2f,lost,\"2 balls, 1 camera\",,,,,,,,2,,,,,,,,,\n", i, 0.1 * i);
    else
      std::snprintf(
          row, sizeof(row), "%d,%.2f,ok,\"\",0.1,0.2,%.4f,1,0,0,0,5,0.12,1e-10,4e-10,9e-10,%.4f,%.4f,%.4f,%.3f,%.3f\n",
          i, 0.1 * i, 1.0 + 0.001 * i, 0.01 * std::sin(i), 0.02 * std::cos(i), -0.03 * std::sin(i), 1.5, 3.0 + i % 5);
    csv += row;
  }
  test::WriteText(d / "poses.csv", csv);
  HtmlReportContents c;
  const std::string html = BuildHtmlReport({d, "track run", 25, 100000}, &c);
  EXPECT_EQ(c.kind, "track");
  const auto figs = EmbeddedFigures(html);
  // status, position, predicted sigma, RMS, error in x, y, z with bands, err_rot_mdeg, NEES.
  ASSERT_EQ(figs.size(), 9u);
  EXPECT_EQ(c.figures, 9u);
  auto find = [&](const std::string& title) -> std::string {
    for (const auto& f : figs)
      if (f.find(title) != std::string::npos) return f;
    ADD_FAILURE() << "no figure titled " << title;
    return "";
  };
  const std::string status = find("Per-frame status");
  EXPECT_NE(status.find("ok (36 frames)"), std::string::npos);
  EXPECT_NE(status.find("lost (4 frames)"), std::string::npos);
  for (const char* axis : {"x", "y", "z"}) {
    const std::string err =
        find(std::string("Error in ") + axis + " against the truth per frame (band: predicted +-3 sigma)");
    EXPECT_EQ(Count(err, "<polygon"), 1u);          // the band
    EXPECT_EQ(Count(err, "<circle cx"), 36u + 1u);  // the tracked frames and the legend's marker
  }
  const std::string nees = find("NEES per frame");
  EXPECT_NE(nees.find("6 dof"), std::string::npos);
  EXPECT_EQ(Count(nees, "<polygon"), 1u);
  EXPECT_NE(nees.find("(log scale)"), std::string::npos);
  EXPECT_NE(html.find("<title>track run</title>"), std::string::npos);
}

// A tracker's poses.csv beside the truth of a rendered recording (truth/poses.csv): the
// page computes the error and NEES per frame, in the covariance's [dtheta; dp] layout.
TEST(HtmlReport, TrackerPosesAreComparedWithTheRenderedTruth) {
  const fs::path d = test::ScratchDir("html_report_truth");
  fs::create_directories(d / "truth");
  const char* axes[] = {"rx", "ry", "rz", "px", "py", "pz"};
  std::string est = "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz,balls,rms_px";
  for (const char* a : axes)
    for (const char* b : axes) est += std::string(",cov_") + a + "_" + b;
  est += "\n";
  std::string truth = "frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz\n";
  // Frame k: the estimate is 1 mm off in x and k * 0.1 mrad about z; sigma 1 mm and 0.1 mrad.
  for (int k = 0; k < 4; ++k) {
    const double half = 0.5 * 1e-4 * k;
    char row[200];
    std::snprintf(row, sizeof(row), "%d,%d,ok,\"\",0.101,0.2,0.9,%.12f,0,0,%.12f,5,0.1", k, k, std::cos(half),
                  -std::sin(half));
    est += row;
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) est += i != j ? ",0" : i < 3 ? ",1e-8" : ",1e-6";
    est += "\n";
    std::snprintf(row, sizeof(row), "%d,%d,0.1,0.2,0.9,1,0,0,0\n", k, k);
    truth += row;
  }
  est += "4,4,lost,\"no balls\",,,,,,,,0,";
  for (int i = 0; i < 36; ++i) est += ",";
  est += "\n";
  // Frames 5-8 are garbage a broken writer could leave (issue 37): a quaternion of norm 5, a
  // NaN position, a negative variance and a variance of 1e308. They are said, never averaged.
  const char* bad[4][2] = {{"5,0,0,0", "1e-6"}, {"1,0,0,0", "1e-6"}, {"1,0,0,0", "-1e-6"}, {"1,0,0,0", "1e308"}};
  for (int k = 5; k < 9; ++k) {
    char row[200];
    std::snprintf(row, sizeof(row), "%d,%d,ok,\"\",%s,0.2,0.9,%s,5,0.1", k, k, k == 6 ? "nan" : "0.101",
                  bad[k - 5][0]);
    est += row;
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) est += i != j ? ",0" : i == 5 ? std::string(",") + bad[k - 5][1] : ",1e-6";
    est += "\n";
    std::snprintf(row, sizeof(row), "%d,%d,0.1,0.2,0.9,1,0,0,0\n", k, k);
    truth += row;
  }
  test::WriteText(d / "poses.csv", est);
  test::WriteText(d / "truth" / "poses.csv", truth);
  HtmlReportContents c;
  const std::string html = BuildHtmlReport({d}, &c);
  EXPECT_EQ(c.kind, "track");
  // NEES = (1 mm / 1 mm)^2 + (k * 0.1 mrad / 0.1 mrad)^2 = 1 + k^2: mean (1 + 2 + 5 + 10) / 4 = 4.5.
  EXPECT_NE(html.find("poses.csv against the truth (matched by frame): 6 of 9 frames, position error RMS 1 mm, "
                      "mean NEES 4.5 (6 for a consistent covariance), 3 of 4 frames inside the 95 % band"),
            std::string::npos);
  EXPECT_NE(html.find("; 2 frame(s) left out: their pose is not seven finite numbers with a unit quaternion; 2 "
                      "frame(s) without a NEES: their covariance is not finite, symmetric and positive definite"),
            std::string::npos)
      << html.substr(html.find("against the truth"), 600);
  EXPECT_EQ(c.figures, 9u);  // status, position, sigma, RMS, errors x, y, z, rotation error, NEES
  // The table on the page carries the new columns: x error +1 mm (estimate - truth, the error
  // of core/statistics.h PoseError, as every NEES in the project), NEES 1 + k^2.
  EXPECT_NE(html.find("<th>nees</th>"), std::string::npos);
  EXPECT_EQ(html.find("<td>-1</td>"), std::string::npos);
  for (const char* v : {"<td>1</td>", "<td>2</td>", "<td>5</td>", "<td>10</td>"})
    EXPECT_NE(html.find(v), std::string::npos) << v;
}

// Files named like text that are not (issue 37: a .txt of 2,408 NUL bytes was pasted into
// the UTF-8 page): listed with the reason, never pasted; real text, UTF-8 included, is.
TEST(HtmlReport, BinaryFilesNamedLikeTextAreNotPasted) {
  const fs::path d = test::ScratchDir("html_report_binary");
  test::WriteText(d / "notes.txt", "caf\xc3\xa9: 3 runs\n");
  test::WriteText(d / "dump.txt", std::string("abc\0\0\0def", 9));
  test::WriteText(d / "model.yaml", "a: \xff\xfe\n");
  test::WriteText(d / "ctl.log", "ok\x01\n");
  HtmlReportContents c;
  const std::string html = BuildHtmlReport({d}, &c);
  EXPECT_EQ(html.find('\0'), std::string::npos) << "a NUL byte on the page";
  EXPECT_NE(html.find("(not shown: dump.txt is not text: a NUL byte at 3)"), std::string::npos);
  EXPECT_NE(html.find("(not shown: model.yaml is not text: a byte that is not UTF-8 at 3)"), std::string::npos);
  EXPECT_NE(html.find("(not shown: ctl.log is not text: control character 1 at 2)"), std::string::npos);
  EXPECT_NE(html.find("caf\xc3\xa9: 3 runs"), std::string::npos) << "UTF-8 text is shown";
}

// Figures each under the per-file cap but many: the page embeds them up to 64 MB in all
// (core/limits.h kMaxEmbeddedBytes) and lists the rest (issue 37: 40 SVGs made a 412 MB page).
TEST(HtmlReport, FiguresAreEmbeddedUpToABoundInAll) {
  const fs::path d = test::ScratchDir("html_report_many_svgs");
  const std::string big = "<svg xmlns=\"http://www.w3.org/2000/svg\"><!--" + std::string(7u << 20, 'x') + "--></svg>\n";
  for (int k = 0; k < 12; ++k) test::WriteText(d / ("fig" + std::to_string(10 + k) + ".svg"), big);
  HtmlReportContents c;
  const std::string html = BuildHtmlReport({d}, &c);
  EXPECT_GE(c.figures, 6);
  EXPECT_LT(c.figures, 12);
  EXPECT_LT(html.size(), size_t{66} << 20);
  EXPECT_NE(html.find("fig21.svg: "), std::string::npos);
  EXPECT_NE(html.find("more would take the page"), std::string::npos);
  EXPECT_NE(html.find("figures beyond 67 MB; not embedded"), std::string::npos);
}

// The first screen of a page (section#answer), "" when it has none; it comes before every
// other section.
std::string AnswerOf(const std::string& html) {
  const size_t b = html.find("<section id=\"answer\"");
  if (b == std::string::npos) return "";
  EXPECT_LT(b, html.find("<h2 id=")) << "the answer comes first";
  return html.substr(b, html.find("</section>", b) - b);
}

struct FirstScreen {
  std::string kind, status, answer;
};

FirstScreen ReportOn(const fs::path& d) {
  HtmlReportContents c;
  const std::string html = BuildHtmlReport({d}, &c);
  return {c.kind, c.status, AnswerOf(html)};
}

// Issue 26: every command's output folder gets a first screen of its own that says what the
// run found, and a run that failed or left nothing says so.
TEST(HtmlReport, EveryCommandsFolderLeadsWithItsAnswer) {
  // An audit that names an effect: its size, held-out gain and the plot that shows it.
  const fs::path audit = test::ScratchDir("first_screen_audit");
  test::WriteText(audit / "report.json", R"J({"mode": "robot", "nominal": {"chi2_per_dof": 4.5, "n": 600},
    "clean": false, "rms_unit": "m", "tests": [{"name": "trend vs joint 2 angle (x)", "statistic": 5,
    "p_value": 1e-9, "failed": true}, {"name": "chi-square", "statistic": 1, "p_value": 0.5, "failed": false}],
    "effects": [{"name": "joint_offset", "where": "joint 2", "parameters": {"offset": 0.00035},
    "sigma": {"offset": 0.00002}, "heldout_rms_before": 0.0004, "heldout_rms_after": 0.00003,
    "heldout_loglik_gain": 812.5, "bic_gain": 900}], "undecided": [["link_length at a2", "joint_scale at joint 2"]],
    "notes": []})J");
  fs::create_directories(audit / "plots");
  SamplePlot().WriteSvg(audit / "plots" / "effect1.svg");
  test::WriteText(audit / "report.txt", "audit (robot)\n");
  FirstScreen f = ReportOn(audit);
  EXPECT_EQ(f.kind, "audit");
  EXPECT_EQ(f.status, "findings");
  for (const char* want : {"The robot audit names 1 effect: joint_offset at joint 2.", "<td>offset = 0.00035 ± 2e-05</td>",
                           "<td>812.5</td>", "trend vs joint 2 angle (x)", "link_length at a2 or joint_scale at joint 2",
                           "plots/effect1.svg"})
    EXPECT_NE(f.answer.find(want), std::string::npos) << want << "\n" << f.answer;
  EXPECT_EQ(f.answer.find("<li>chi-square</li>"), std::string::npos) << "only the failed tests";
  // A clean audit, and one whose failures no catalog effect explains.
  test::WriteText(audit / "report.json", R"J({"mode": "cameras", "nominal": {"chi2_per_dof": 1.01, "n": 900},
    "clean": true, "rms_unit": "px", "tests": [{"name": "x", "statistic": 1, "p_value": 0.5, "failed": false}],
    "effects": [], "undecided": [], "notes": []})J");
  f = ReportOn(audit);
  EXPECT_EQ(f.status, "ok");
  EXPECT_NE(f.answer.find("No effect found: the nominal model explains the cameras data within its noise (chi2/dof 1.010"),
            std::string::npos) << f.answer;
  test::WriteText(audit / "report.json", R"J({"mode": "cameras", "nominal": {"chi2_per_dof": 24.6, "n": 900},
    "clean": false, "tests": [{"name": "pixel noise scale of cam2", "statistic": 10, "p_value": 0, "failed": true}],
    "effects": [], "undecided": [], "notes": []})J");
  f = ReportOn(audit);
  EXPECT_EQ(f.status, "findings");
  EXPECT_NE(f.answer.find("does not explain the cameras data (chi2/dof 24.600; 1 of 1 tests failed), and no effect of "
                          "the catalog explains it"), std::string::npos) << f.answer;
  test::WriteText(audit / "report.json", "{\"mode\": \"cameras\"}");
  EXPECT_EQ(ReportOn(audit).status, "failed");

  // fov-map: the region below the threshold, and sigma against distance.
  const fs::path fov = test::ScratchDir("first_screen_fov");
  test::WriteText(fov / "region.txt", "# Predicted precision\ngrid a: 8 points\nbest  sigma_d 0.0140 mm at (0, 0, 1) m\n"
                                      "worst sigma_d 0.0322 mm at (0, 0, 0) m\nsigma_d < 0.03 mm at 7 of 8 grid points (87.5 %)\n");
  test::WriteText(fov / "map.csv", "x_m,sigma_d_mm\n0,0.01\n");
  SamplePlot().WriteSvg(fov / "sigma_vs_distance.svg");
  f = ReportOn(fov);
  EXPECT_EQ(f.kind, "fov-map");
  EXPECT_NE(f.answer.find("The rig measures with sigma_d &lt; 0.03 mm at 7 of 8 grid points (87.5 %)."), std::string::npos)
      << f.answer;
  EXPECT_NE(f.answer.find("worst sigma_d 0.0322 mm"), std::string::npos);
  EXPECT_NE(f.answer.find("sigma_vs_distance.svg"), std::string::npos);

  // calib-rig: each camera's fit and the residual against the noise floor.
  const fs::path rig = test::ScratchDir("first_screen_calib_rig");
  test::WriteText(rig / "rig.yaml", "cameras: []\n");
  SamplePlot().WriteSvg(rig / "residuals-left.svg");
  test::WriteText(rig / "summary.txt",
                  "residual RMS 0.2100 px per coordinate, 1400 inlier points, 2 rejected\nlast solve: 9 iterations, converged\n"
                  "left: 13 views, 700/702 points, RMS 0.2000 px per coordinate (0.2800 px per point), max 1.2000 px\n"
                  "  LENSMODEL_OPENCV8 intrinsics (+- 1 sigma): 530 +- 0.4\n"
                  "right: 13 views, 698/700 points, RMS 0.2200 px per coordinate (0.3100 px per point), max 1.4000 px\n"
                  "residual against the views' own noise floor (each view's board pose fitted alone): 0.21 / 0.20 px per "
                  "coordinate = 1.05\n");
  f = ReportOn(rig);
  EXPECT_EQ(f.kind, "calib-rig");
  EXPECT_EQ(f.status, "ok");
  for (const char* want : {"<td>left</td><td>13</td><td>700/702</td><td>0.2000</td><td>1.2000</td>",
                           "<td>right</td><td>13</td><td>698/700</td><td>0.2200</td><td>1.4000</td>", "= 1.05",
                           "residuals-left.svg"})
    EXPECT_NE(f.answer.find(want), std::string::npos) << want << "\n" << f.answer;
  fs::remove(rig / "summary.txt");
  EXPECT_EQ(ReportOn(rig).status, "failed");

  // calib-robot: the residuals before and after, held out.
  const fs::path robot = test::ScratchDir("first_screen_calib_robot");
  test::WriteText(robot / "calib.txt", "# mcms calib-robot report\nrobot: kr5 (6 joints)\n"
                                       "solver: converged after 7 iterations; variance factor 1.02; observability index 0.01\n"
                                       "residuals, nominal DH registered:     RMS 0.4100 mm, max 0.9 mm\n"
                                       "residuals, calibrated:                RMS 0.0300 mm, max 0.08 mm\n"
                                       "held out (5-fold), calibrated: RMS 0.0350 mm, max 0.1 mm\n");
  f = ReportOn(robot);
  EXPECT_EQ(f.kind, "calib-robot");
  for (const char* want : {"converged after 7 iterations", "<td>residuals, calibrated</td><td>RMS 0.0300 mm, max 0.08 mm</td>",
                           "<td>held out (5-fold), calibrated</td>"})
    EXPECT_NE(f.answer.find(want), std::string::npos) << want << "\n" << f.answer;

  // iso9283: AP and RP per condition.
  const fs::path iso = test::ScratchDir("first_screen_iso");
  test::WriteText(iso / "iso.csv", "condition,pose,AP_mm,RP_mm\nbefore,P1,0.8,0.04\nbefore,P2,1.0,0.03\nafter,P1,0.1,0.04\n"
                                   "after,P2,0.05,0.03\n");
  f = ReportOn(iso);
  EXPECT_EQ(f.kind, "iso9283");
  EXPECT_NE(f.answer.find("<td>before</td><td>2</td><td>0.9000</td><td>1.0000</td><td>0.0350</td><td>0.0400</td>"),
            std::string::npos) << f.answer;
  EXPECT_LT(f.answer.find("<td>before</td>"), f.answer.find("<td>after</td>")) << "in the file's order";

  // fuse: rows per method, flagged sensors, the predicted sigma.
  const fs::path fuse = test::ScratchDir("first_screen_fuse");
  test::WriteText(fuse / "fused.csv", "frame,time_s,method,x_m,sensors,flagged,excluded,cov_px_px,cov_py_py,cov_pz_pz\n"
                                      "0,1,moifa,0.1,camera;robot,,,1e-10,1e-10,2e-10\n"
                                      "0,1,kf,0.1,camera;robot,robot,,1e-10,1e-10,2e-10\n");
  f = ReportOn(fuse);
  EXPECT_EQ(f.kind, "fuse");
  EXPECT_EQ(f.status, "findings");
  EXPECT_NE(f.answer.find("fused.csv: 2 fused poses by 2 methods; 1 with a sensor flagged as inconsistent."),
            std::string::npos) << f.answer;
  EXPECT_NE(f.answer.find("<td>kf</td><td>1</td><td>1</td><td>0</td><td>0.0200</td>"), std::string::npos) << f.answer;

  // A tracker that tracked nothing, and one that wrote only its header: failed, said first.
  const fs::path lost = test::ScratchDir("first_screen_lost");
  test::WriteText(lost / "poses.csv", "frame,time_s,status,x_m\n0,0,lost,\n1,0.1,lost,\n");
  f = ReportOn(lost);
  EXPECT_EQ(f.status, "failed");
  EXPECT_NE(f.answer.find("No frame tracked: all 2 frames of poses.csv are lost."), std::string::npos) << f.answer;
  test::WriteText(lost / "poses.csv", "frame,time_s,status,x_m\n");
  EXPECT_NE(ReportOn(lost).answer.find("poses.csv holds no frame"), std::string::npos);
  // A demo that stopped before its summary.
  const fs::path demo = test::ScratchDir("first_screen_demo_failed");
  test::WriteText(demo / "point_errors.csv", "point,camera_pos_err_mm\n0,0.1\n");
  test::WriteText(demo / "fused_poses.csv", "frame,time_s\n0,1\n");
  f = ReportOn(demo);
  EXPECT_EQ(f.status, "failed");
  EXPECT_NE(f.answer.find("The demo did not finish"), std::string::npos);
  // An empty folder, and one with nothing a page can show: a page that says so.
  const fs::path empty = test::ScratchDir("first_screen_empty");
  f = ReportOn(empty);
  EXPECT_EQ(f.status, "empty");
  EXPECT_NE(f.answer.find("Nothing to report: "), std::string::npos);
  EXPECT_NE(f.answer.find(" holds no file. The command that should have written it failed or has not run"),
            std::string::npos) << f.answer;
  test::WriteText(empty / "x.bin", "x");
  EXPECT_NE(ReportOn(empty).answer.find("holds no result file"), std::string::npos);
}

TEST(HtmlReport, BadFolderOrOutputIsRefusedAndNothingWritten) {
  const fs::path d = test::ScratchDir("html_report_bad");
  EXPECT_NE(test::ErrorOf([&] { BuildHtmlReport({d / "missing"}); }).find("missing does not exist"), std::string::npos);
  test::WriteText(d / "file.txt", "x");
  EXPECT_NE(test::ErrorOf([&] { BuildHtmlReport({d / "file.txt"}); }).find("is not a folder"), std::string::npos);

  // An output that is a folder: refused before anything is built.
  fs::create_directories(d / "run" / "out.html");
  test::WriteText(d / "run" / "summary.txt", "ok");
  EXPECT_NE(test::ErrorOf([&] { WriteHtmlReport({d / "run"}, d / "run" / "out.html"); }).find("is a folder"),
            std::string::npos);
  // A failing build leaves no file.
  EXPECT_THROW(WriteHtmlReport({d / "missing"}, d / "missing.html"), InputError);
  EXPECT_FALSE(fs::exists(d / "missing.html"));
  // A good run writes the page; a report.html in the folder is not reported on itself.
  WriteHtmlReport({d / "run"}, d / "run" / "report.html");
  const std::string first = test::ReadAll(d / "run" / "report.html");
  WriteHtmlReport({d / "run"}, d / "run" / "report.html");
  EXPECT_EQ(test::ReadAll(d / "run" / "report.html"), first);  // deterministic, and does not include itself
}

// Tick labels of the y axis: the text of every right-aligned label.
std::vector<std::string> YTickLabels(const std::string& svg) {
  std::vector<std::string> out;
  const std::regex re("text-anchor='end'>([^<]*)</text>");
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), re); it != std::sregex_iterator(); ++it)
    out.push_back((*it)[1]);
  return out;
}

TEST(SvgPlot, LogAxisIsLabelledInRealUnits) {
  Plot p = SamplePlot();
  p.log_y = true;
  const std::string svg = p.ToSvg();
  const auto labels = YTickLabels(svg);
  ASSERT_GE(labels.size(), 4u);
  // Ticks from 0.002 up to 1: real values, not the exponents -3..0.
  EXPECT_EQ(labels.front(), "0.002");
  EXPECT_EQ(labels.back(), "1");
  for (const char* v : {"0.01", "0.1"}) EXPECT_NE(std::find(labels.begin(), labels.end(), v), labels.end()) << v;
  for (const auto& l : labels) EXPECT_GT(std::stod(l), 0) << l;
  EXPECT_NE(svg.find("error (mm) (log scale)"), std::string::npos);
  EXPECT_NE(svg.find("Errors &lt;per&gt; point &amp; more"), std::string::npos);
}

TEST(SvgPlot, LegendSitsAboveThePlotAreaAndLinearTicksHaveNoRoundingNoise) {
  Plot p = SamplePlot();
  for (int k = 0; k < 6; ++k)
    p.series.push_back(
        PlotSeries{"a rather long series label number " + std::to_string(k), {0.5, 2.0}, {-0.3, 0.6}, "#000", false});
  const std::string svg = p.ToSvg(900, 420);
  // The plot area is the framed rect; every legend label is above its top edge.
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      svg, m, std::regex("<rect x='80' y='([0-9.]+)' width='[0-9.]+' height='[0-9.]+' fill='none' stroke='black'/>")));
  const double top = std::stod(m[1]);
  const std::regex legend("<text x='[0-9.]+' y='([0-9.]+)'>(measured|predicted|a rather long[^<]*)</text>");
  int n = 0;
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), legend); it != std::sregex_iterator(); ++it, ++n)
    EXPECT_LT(std::stod((*it)[1]), top) << (*it)[2];
  EXPECT_EQ(n, 8);
  EXPECT_GT(top, 60.0);  // the legend wrapped to more than one row
  // Ticks through zero read 0, not 1e-17.
  for (const auto& l : YTickLabels(svg)) EXPECT_EQ(l.find("e-"), std::string::npos) << l;
}

TEST(SvgPlot, ResidualVectorsOverTheImageKeepImageAxes) {
  // Residuals of 0.5 px drawn 100 times magnified over a 640 x 480 image, rows downwards.
  Plot p{"residuals over the image", "u (px)", "v (px)", {}};
  p.y_down = true;
  p.equal_scale = true;
  p.x_range = {{0.0, 640.0}};
  p.y_range = {{0.0, 480.0}};
  PlotSeries r{"residual x 100", {100, 500}, {20, 400}, "#d62728", true};
  r.dx = {0.5, 0.0};
  r.dy = {0.0, -0.5};
  r.vector_scale = 100;
  p.series = {r};
  const std::string svg = p.ToSvg(900, 600);
  // Two arrow shafts, two heads; the base markers at the points.
  const std::regex shaft(
      "<line x1='([0-9.]+)' y1='([0-9.]+)' x2='([0-9.]+)' y2='([0-9.]+)' stroke='#d62728' stroke-width='1'/>");
  std::vector<std::array<double, 4>> shafts;
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), shaft); it != std::sregex_iterator(); ++it)
    shafts.push_back({std::stod((*it)[1]), std::stod((*it)[2]), std::stod((*it)[3]), std::stod((*it)[4])});
  ASSERT_EQ(shafts.size(), 2u);
  EXPECT_EQ(Count(svg, "<polyline fill='none' stroke='#d62728'"), 2u);
  // The first points right (+u), 50 px of image long; the second points up the image (-v).
  EXPECT_GT(shafts[0][2], shafts[0][0]);
  EXPECT_NEAR(shafts[0][3], shafts[0][1], 0.11);
  EXPECT_LT(shafts[1][3], shafts[1][1]);
  // Rows downwards: v = 20 is above v = 400; equal scale: 50 px of image are as long on both axes.
  EXPECT_LT(shafts[0][1], shafts[1][1]);
  EXPECT_NEAR(shafts[0][2] - shafts[0][0], shafts[1][1] - shafts[1][3], 0.2);
  // The axes span the image: ticks from 0 to 600 px.
  EXPECT_NE(svg.find(">600</text>"), std::string::npos);
  EXPECT_NE(svg.find(">0</text>"), std::string::npos);
}

TEST(SvgPlot, GridPlacesEachPlotInItsCell) {
  std::vector<Plot> plots(5, SamplePlot());
  for (int i = 0; i < 5; ++i) plots[i].title = "panel " + std::to_string(i);
  const std::string svg = PlotGridSvg(plots, 3, 400, 300);
  // 3 columns, 2 rows; each panel a nested viewport at its cell, all titles present.
  EXPECT_EQ(svg.rfind("<svg xmlns='http://www.w3.org/2000/svg' width='1200' height='600'", 0), 0u)
      << svg.substr(0, 120);
  for (const char* cell :
       {"<svg x='0' y='0'", "<svg x='400' y='0'", "<svg x='800' y='0'", "<svg x='0' y='300'", "<svg x='400' y='300'"})
    EXPECT_EQ(Count(svg, cell), 1u) << cell;
  EXPECT_EQ(Count(svg, "<svg"), 6u);
  EXPECT_EQ(Count(svg, "</svg>"), 6u);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(Count(svg, ">panel " + std::to_string(i) + "<"), 1u) << i;
  EXPECT_THROW(PlotGridSvg({}, 3), InternalError);
  EXPECT_THROW(PlotGridSvg(plots, 0), InternalError);
}

// Issue 54: the command that wrote a folder is the one its .mcms-output records, not a guess
// from its files' names; a folder without a record is still recognised by its files.
TEST(HtmlReport, TheCommandIsTheOneTheFolderRecords) {
  const fs::path d = test::ScratchDir("html_report_recorded_kind");
  // Files a tracker would write, in a folder calib-rig wrote (its record says so).
  test::WriteText(d / "poses.csv", "frame,time_s,status,x_m,y_m,z_m,qw,qx,qy,qz\n0,0,ok,0,0,1,1,0,0,0\n");
  EXPECT_EQ(ReportOn(d).kind, "track");  // no record: guessed from the files
  RecordOutputFolder(d, "calib-rig");
  EXPECT_EQ(ReportOn(d).kind, "calib-rig");
  RecordOutputFolder(d, "audit lens");  // every audit mode is an audit
  EXPECT_EQ(ReportOn(d).kind, "audit");
  RecordOutputFolder(d, "render");  // a command without a first screen of its own: the files decide
  EXPECT_EQ(ReportOn(d).kind, "track");
}

}  // namespace
}  // namespace mcms
