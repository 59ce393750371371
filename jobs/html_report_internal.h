// What the pieces of `mcms report` share (jobs/html_report.h is the entry): the page's
// building blocks (html_report_html.cpp), the plots of known tables
// (html_report_plots.cpp), what the folder came from and its first screen
// (html_report_answers.cpp). Internal to the report: not for other modules.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace mcms::html_report_internal {

// ---- the page's building blocks (html_report_html.cpp) --------------------------------
// Why `s` is not UTF-8 text ("" when it is).
std::string NotText(const std::string& s);
std::string Html(const std::string& s);  // escaped for HTML text and attributes
std::string Lower(std::string s);
bool StartsWith(const std::string& s, const std::string& p);
std::string Num(double v);       // 6 significant digits
std::string Bytes(uintmax_t n);  // "12 kB"

// A CSV's cells with the lookups a report needs: a missing column is -1, a cell that is
// not a finite number nullopt; its '#' comment lines kept.
struct Table {
  std::vector<std::string> comments, header;
  std::vector<std::vector<std::string>> rows;
  int Column(const std::string& name) const {
    for (size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return static_cast<int>(i);
    return -1;
  }
  // Number in a cell; nullopt when empty or not a finite number.
  std::optional<double> Value(size_t row, int col) const {
    if (col < 0 || row >= rows.size() || static_cast<size_t>(col) >= rows[row].size()) return std::nullopt;
    const std::string& c = rows[row][col];
    if (c.empty()) return std::nullopt;
    char* end = nullptr;
    const double v = std::strtod(c.c_str(), &end);
    if (end != c.c_str() + c.size() || !std::isfinite(v)) return std::nullopt;
    return v;
  }
};

// A CSV read by the one reader (core/io.h ReadCsv); on a malformed table its message in
// *error, and the page says the table was not shown.
Table ReadTable(const std::filesystem::path& path, std::string* error);

struct File {
  std::filesystem::path path;
  std::string name;  // relative to the report folder
  uintmax_t size = 0;
  bool link = false;  // a symbolic link: listed, never read
};

std::string FigureHtml(const std::string& svg, const std::string& caption);
std::string Note(const std::string& s);
// A table as HTML: all rows when short, per-column statistics and the first and last rows
// when longer than max_rows.
std::string TableHtml(const Table& t, size_t max_rows);

// ---- plots of the tables the commands write (html_report_plots.cpp) -------------------
bool IsTrackerPoses(const Table& t);
bool IsFusedPoses(const Table& t);
bool IsIso9283Characteristics(const Table& t);
// 95 % two-sided band of a chi-square variable with k degrees of freedom.
std::pair<double, double> ChiSquareBand95(int k);
// A tracker's poses joined with the truth's by frame; "" or why not.
std::string AddTruthColumns(Table& t, const Table& truth);
// The plots of a tracker's poses and of ISO 9283's characteristics into `out`; how many.
size_t TrackerPlots(const Table& t, const std::string& name, std::ostringstream& out);
size_t Iso9283Plots(const Table& t, const std::string& name, std::ostringstream& out);

// ---- what the folder came from, and the first screen (html_report_answers.cpp) --------
// The command that wrote the folder: the one its `.mcms-output` records (`recorded`, "" when
// it has none; every "audit ..." is "audit"), else guessed from its files (a folder written
// by a command that keeps no record: track, fuse, calib-robot, an audit's > FILE).
std::string DetectKind(const std::string& recorded, const std::vector<File>& files,
                       const std::map<std::string, Table>& tables, const std::map<std::string, std::string>& texts);

// ---- The first screen (issue 26): what the run found, before everything else ----------
// One section#answer per page: a sentence that says what the run found (or that it failed,
// or that the folder is empty), a small table of the figures that matter, and at most one
// plot, the one that shows the finding. Its class (ok, findings, failed, empty) colours its
// bar, so a failed run cannot be mistaken for a clean one.
struct Answer {
  std::string status = "ok";
  std::string lead;  // plain text
  std::string html;  // tables, notes, one figure
};

std::string AnswerHtml(const Answer& a);
// The first screen of a page: by what the folder came from; a demo without its summary,
// a tracker that tracked nothing, an audit that did not finish say so.
Answer FirstScreen(const std::string& kind, const std::map<std::string, Table>& tables,
                   const std::map<std::string, std::string>& texts, const std::vector<const File*>& svgs);

}  // namespace mcms::html_report_internal
