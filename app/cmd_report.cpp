// mcms report: one self-contained HTML page (no network) for the output folder of another
// mcms command (demo, fov-map, calib-rig, track, iso9283, calib-robot, audit). The page is
// built by jobs/html_report.h; this file parses the options and prints what it wrote.
#include <cstdio>
#include <memory>
#include <string>

#include "app/commands.h"
#include "jobs/html_report.h"

namespace mcms::app {
namespace {

McmsCommand report_command([](CLI::App& app) {
  auto opts = std::make_shared<HtmlReportOptions>();
  auto out = std::make_shared<std::string>();
  auto dir = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand(
      "report",
      "Write one self-contained HTML page (no network, opens in any browser) for the output folder of another mcms "
      "command: its summaries and reports, every SVG figure, its tables (long ones summarised per column), its "
      "input and model files, and per-frame plots of a tracker poses.csv (status, position, predicted sigma; error "
      "with its 3-sigma band and NEES when the CSV has truth columns).");
  cmd->add_option("DIR", *dir, "output folder of an mcms command (e.g. what `mcms demo -o DIR` wrote)")->required();
  cmd->add_option("-o,--output", *out, "HTML file to write (default DIR/report.html)")->type_name("FILE.html");
  cmd->add_option("--title", opts->title, "page title (default: mcms report: <folder name>)");
  cmd->add_option("--max-table-rows", opts->max_table_rows, "tables longer than this are summarised (default 25)")
      ->check(CLI::Range(1, 100000));
  return std::make_pair(cmd, Runner([opts, out, dir] {
                          opts->dir = *dir;
                          const std::filesystem::path file =
                              out->empty() ? std::filesystem::path(*dir) / "report.html" : std::filesystem::path(*out);
                          const HtmlReportContents c = WriteHtmlReport(*opts, file);
                          std::printf("wrote %s: the output of %s, %zu figures, %zu tables, %zu reports, %zu inputs\n",
                                      file.string().c_str(), c.kind == "mcms output" ? "an mcms command" : ("mcms " + c.kind).c_str(),
                                      c.figures, c.tables, c.texts, c.inputs);
                          if (c.status == "failed" || c.status == "empty")
                            std::fprintf(stderr, "mcms report: note: %s %s; its first screen says so\n", dir->c_str(),
                                         c.status == "empty" ? "holds no result" : "is the output of a run that failed");
                          return 0;
                        }));
});

}  // namespace
}  // namespace mcms::app
