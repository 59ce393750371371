// One self-contained HTML page for the output folder of an mcms command (`mcms report`):
// the run's summaries and reports, every figure, every table and the input/model files,
// with no network access and nothing outside the page (figures are embedded as data URIs,
// the style is inline, the only script is a few inline lines that count the figures the
// browser rendered and log one console line).
//
// What the folder holds decides what the page shows; files are recognised by their
// extension and, for the folders of known commands, by their names and CSV columns:
//   *.svg                      figures (the plots of core/svg_plot), embedded as images
//   *.csv                      HTML tables: shown whole up to `max_table_rows` rows, otherwise
//                              summarised (rows, per-column min / median / max / mean for
//                              numeric columns, counts for text columns) with the whole table
//                              sortable by any column (a click on its header) in a folded
//                              section, up to 2,000 rows (first and last rows beyond)
//   *.txt, *.md, *.log         reports, as preformatted text folded away below the figures
//                              (summary*.txt first; the first 60 lines of a long one, the
//                              rest in a further collapsed section)
//   *.yaml, *.yml, *.json,     inputs and models, in collapsed sections (*.html files, earlier
//                              reports, are left out)
//   *.cameramodel
//   anything else, subfolders  listed with their size (an images/ folder is counted, not
//                              embedded)
// A tracker pose CSV (`mcms track`'s poses.csv: frame, time_s, status, ..., covariance) also
// gets per-frame plots: the status and the number of balls seen, the position, the
// predicted sigma next to the reprojection RMS, and, when the CSV carries error columns
// against a truth file (err_*_mm) and a nees column, the error with its predicted 3-sigma
// band and the NEES with its 95 % chi-square band.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace mcms {

struct HtmlReportOptions {
  std::filesystem::path dir;        // the output folder of an mcms command
  std::string title;                // default: "mcms report: <folder name>"
  size_t max_table_rows = 25;       // longer tables are summarised
  size_t max_text_bytes = 100000;   // longer text files are cut, with a note
  bool IsValid(std::string* why = nullptr) const;
};

struct HtmlReportContents {
  // What the folder looks like it came from: "demo", "fov-map", "calib-rig", "track",
  // "iso9283", "calib-robot", "audit", or "mcms output" when no rule matched.
  std::string kind;
  // What the page's first screen says of the run: "ok", "findings" (an audit named effects,
  // a sensor was flagged, a fit warned), "failed" (the run did not finish or tracked
  // nothing) or "empty" (the folder holds no result file).
  std::string status;
  size_t figures = 0;   // SVG images on the page (files and plots made from CSVs)
  size_t tables = 0, texts = 0, inputs = 0;
  std::vector<std::string> listed;  // files listed but not embedded
};

// The page, led by its first screen: what the run found (or that it failed, or that the
// folder is empty). InputError naming the folder when it is not a readable folder. An SVG
// file that is not an SVG document, or a CSV that cannot be parsed, is shown as a note on
// the page (naming the file and the problem), not skipped silently.
std::string BuildHtmlReport(const HtmlReportOptions& options, HtmlReportContents* contents = nullptr);

// Builds the page and writes it atomically (core/io.h): the output is checked for
// writability first, and an existing file is replaced only when complete.
HtmlReportContents WriteHtmlReport(const HtmlReportOptions& options, const std::filesystem::path& output);

}  // namespace mcms
