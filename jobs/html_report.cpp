#include "jobs/html_report.h"

#include <Eigen/Cholesky>
#include <numbers>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <system_error>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/output_folder.h"
#include "core/pose_math.h"
#include "core/statistics.h"
#include "core/svg_plot.h"
#include "jobs/html_report_internal.h"

namespace mcms {

namespace fs = std::filesystem;

bool HtmlReportOptions::IsValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (dir.empty()) return fail("the folder to report on is empty");
  if (max_table_rows < 1) return fail("max_table_rows must be at least 1");
  if (max_text_bytes < 100) return fail("max_text_bytes must be at least 100");
  return true;
}
using namespace html_report_internal;

namespace {

constexpr size_t kMaxSvgBytes = size_t{8} << 20;  // a larger SVG is listed, not embedded
constexpr size_t kReportHeadLines = 60;           // lines of a long report shown before "more"

const char* kStyle = R"(body{font-family:sans-serif;margin:24px auto;max-width:1200px;color:#222;padding:0 16px}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:1.8em}h3{font-size:1.05em;margin-top:1.4em}
pre{background:#f6f6f6;padding:10px;overflow-x:auto;font-size:12px;line-height:1.35}
figure{margin:18px 0}figure img{max-width:100%;height:auto;border:1px solid #ddd}figcaption{font-size:13px;color:#555}
table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right;white-space:nowrap}
th{background:#eee}.scroll{overflow-x:auto;max-width:100%}.note{color:#a00}.comment{font-family:monospace;font-size:12px;color:#555}
td.gap{text-align:center;color:#777}ul.files{columns:2;font-size:13px}summary{cursor:pointer;font-weight:bold}
table.headline{font-size:15px}table.headline td:first-child{text-align:left}table.headline tr.fused{font-weight:bold}
section.answer{border-left:6px solid #2ca02c;padding:2px 14px 8px;background:#f7fbf7}section.answer h2{margin-top:.4em}
section.answer.findings{border-color:#ff7f0e;background:#fffaf3}section.answer.failed,section.answer.empty{border-color:#d62728;background:#fdf5f5}
p.lead{font-size:17px}table.headline td,table.headline th{white-space:normal}summary h3{display:inline}div.tall{max-height:420px;overflow-y:auto}
table.sortable th{cursor:pointer}table.sortable th.sorted-up:after{content:" \25B2"}table.sortable th.sorted-down:after{content:" \25BC"})";

// Counts the figures the browser decoded and logs one console line: an error naming the
// figures that did not render, otherwise a plain log line.
const char* kScript = R"(window.addEventListener('load', function () {
  var imgs = document.querySelectorAll('img.figure'), ok = 0, bad = [];
  for (var i = 0; i < imgs.length; ++i) {
    if (imgs[i].complete && imgs[i].naturalWidth > 0) ++ok; else bad.push(imgs[i].alt);
  }
  document.body.setAttribute('data-figures', String(imgs.length));
  document.body.setAttribute('data-figures-rendered', String(ok));
  // Where the first screen's headline ends (the lead and its first table), so that a test
  // can check it is visible without scrolling.
  var answer = document.getElementById('answer');
  if (answer) {
    var bottom = 0;
    answer.querySelectorAll('p.lead, table.headline').forEach(function (e) {
      bottom = Math.max(bottom, e.getBoundingClientRect().bottom);
    });
    document.body.setAttribute('data-headline-bottom', String(Math.round(bottom)));
    document.body.setAttribute('data-answer-status', answer.className.replace('answer ', ''));
  }
  if (bad.length) console.error('mcms report: figures not rendered: ' + bad.join(', '));
  else console.log('mcms report: ' + ok + ' of ' + imgs.length + ' figures rendered');
  // Long tables sort by a column on a click of its header (numbers as numbers).
  document.querySelectorAll('table.sortable th').forEach(function (th) {
    th.addEventListener('click', function () {
      var table = th.closest('table'), body = table.tBodies[0], col = th.cellIndex;
      var up = !th.classList.contains('sorted-up');
      table.querySelectorAll('th').forEach(function (h) { h.classList.remove('sorted-up', 'sorted-down'); });
      th.classList.add(up ? 'sorted-up' : 'sorted-down');
      var rows = Array.prototype.filter.call(body.rows, function (r) { return r.cells.length > col; });
      var key = function (r) { var t = r.cells[col].textContent, v = parseFloat(t); return isNaN(v) ? t : v; };
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        var d = typeof x === typeof y ? (x < y ? -1 : x > y ? 1 : 0) : (typeof x === 'number' ? -1 : 1);
        return up ? d : -d;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});)";

}  // namespace

// The folder a report is made of: it exists and is a folder.
void RequireReportFolder(const fs::path& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec))
    Throw("mcms report DIR: ", dir.string(), " does not exist; expected the output folder of an mcms command");
  if (!fs::is_directory(dir, ec))
    Throw("mcms report DIR: ", dir.string(), " is not a folder; expected the output folder of an mcms command");
}

// The files of an output folder (and of its plots/ subfolder, named "plots/<file>"), in name
// order, and its other subfolders with their file counts; hidden files, temporaries of an atomic write and earlier HTML pages left out.
void ListFolder(const fs::path& dir, std::vector<File>* files_out,
                std::vector<std::pair<std::string, size_t>>* folders_out) {
  std::vector<File>& files = *files_out;
  std::vector<std::pair<std::string, size_t>>& folders = *folders_out;
  std::error_code ec;
  fs::directory_iterator it(dir, ec);
  if (ec) Throw("mcms report DIR: cannot read the folder ", dir.string(), ": ", ec.message());
  for (const auto& e : it) {
    const std::string name = e.path().filename().string();
    // Hidden files, temporaries of an atomic write, and HTML pages (earlier reports) are
    // not part of the run.
    if (name.empty() || name[0] == '.' || name.find(".partial-") != std::string::npos ||
        Lower(e.path().extension().string()) == ".html")
      continue;
    if (e.is_symlink(ec)) {
      // A link is listed, never followed: it may name any file of the system (issue 53).
      files.push_back({e.path(), name + " (a symbolic link, not followed)", 0, true});
      continue;
    }
    if (e.is_directory(ec) && name == "plots") {
      // The audits' plots/ folder: its figures are part of the run (the first screen shows
      // the one of a named effect).
      std::vector<File> plots;
      for (const auto& p : fs::directory_iterator(e.path(), ec))
        if (!p.is_symlink(ec) && p.is_regular_file(ec) && p.path().filename().string()[0] != '.' &&
            p.path().filename().string().find(".partial-") == std::string::npos)
          plots.push_back({p.path(), "plots/" + p.path().filename().string(), p.file_size(ec)});
      files.insert(files.end(), plots.begin(), plots.end());
    } else if (e.is_directory(ec)) {
      size_t count = 0;
      for (auto sub = fs::recursive_directory_iterator(e.path(), fs::directory_options::skip_permission_denied, ec);
           !ec && sub != fs::recursive_directory_iterator(); sub.increment(ec))
        if (sub->is_regular_file(ec)) ++count;
      folders.push_back({name, count});
    } else if (e.is_regular_file(ec)) {
      files.push_back({e.path(), name, e.file_size(ec)});
    }
  }
  std::sort(files.begin(), files.end(), [](const File& a, const File& b) { return a.name < b.name; });
  std::sort(folders.begin(), folders.end());
}

std::string BuildHtmlReport(const HtmlReportOptions& options, HtmlReportContents* contents) {
  std::string why;
  if (!options.IsValid(&why)) Throw("mcms report: ", why);
  const fs::path& dir = options.dir;
  RequireReportFolder(dir);
  std::error_code ec;
  std::vector<File> files;  // the folder's files in name order, and its subfolders counted
  std::vector<std::pair<std::string, size_t>> folders;
  ListFolder(dir, &files, &folders);
  HtmlReportContents c;
  std::vector<const File*> svgs, csvs, reports, inputs, others;
  for (const auto& f : files) {
    const std::string ext = Lower(f.path.extension().string());
    (f.link               ? others
     : ext == ".svg"                                                                ? svgs
     : ext == ".csv"                                                              ? csvs
     : ext == ".txt" || ext == ".md" || ext == ".log"                             ? reports
     : ext == ".yaml" || ext == ".yml" || ext == ".json" || ext == ".cameramodel" ? inputs
                                                                                  : others)
        .push_back(&f);
  }

  // Read what is shown (bounded sizes), parse the tables.
  std::map<std::string, std::string> texts;  // name -> text (reports and inputs)
  std::map<std::string, Table> tables;
  std::map<std::string, std::string> table_errors;
  auto read_bounded = [&](const File& f, size_t limit, bool* cut) {
    if (f.size > limit) {
      std::ifstream in(f.path, std::ios::binary);
      std::string s(limit, '\0');
      in.read(s.data(), static_cast<std::streamsize>(limit));
      s.resize(static_cast<size_t>(in.gcount()));
      *cut = true;
      return s;
    }
    *cut = false;
    return ReadTextFile(f.path);
  };
  std::map<std::string, bool> cut;
  for (const auto* group : {&reports, &inputs})
    for (const File* f : *group) {
      bool was_cut = false;
      texts[f->name] = read_bounded(*f, options.max_text_bytes, &was_cut);
      cut[f->name] = was_cut;
      // A file named like text that is not (NUL bytes, control characters, bytes that are
      // not UTF-8) is listed, not pasted into the UTF-8 page (issue 37).
      if (const std::string why = NotText(texts[f->name]); !why.empty()) {
        texts[f->name] = "(not shown: " + f->name + " is not text: " + why + ")";
        cut[f->name] = false;
      }
    }
  for (const File* f : csvs) {
    if (f->size > kMaxTextFileBytes) {
      table_errors[f->name] = "larger than " + Bytes(kMaxTextFileBytes) + ", not read";
      continue;
    }
    std::string err;
    Table t = ReadTable(f->path, &err);
    if (!err.empty())
      table_errors[f->name] = err;
    else
      tables[f->name] = std::move(t);
  }
  // A tracker pose table beside the truth of a rendered recording (`mcms render` writes
  // truth/poses.csv, `mcms track DIR` poses.csv): errors and NEES against the truth, unless
  // the table carries them already.
  std::vector<std::string> truth_notes;
  const fs::path truth_file = dir / "truth" / "poses.csv";
  for (auto& [name, t] : tables) {
    if (!IsTrackerPoses(t) || t.Column("nees") >= 0 || !fs::is_regular_file(truth_file, ec)) continue;
    std::string err;
    const Table truth = ReadTable(truth_file, &err);
    truth_notes.push_back(name + " " +
                          (err.empty() ? AddTruthColumns(t, truth) : "not compared with truth/poses.csv: " + err));
  }
  c.kind = DetectKind(RecordedOutputKind(dir), files, tables, texts);

  std::ostringstream o;
  const std::string title = options.title.empty()
                                ? "mcms report: " + fs::absolute(dir).lexically_normal().filename().string()
                                : options.title;
  o << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" << Html(title) << "</title>\n"
    << "<meta name=\"generator\" content=\"mcms report\">\n"
    << "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src data:; style-src "
       "'unsafe-inline'; "
       "script-src 'unsafe-inline'\">\n<style>"
    << kStyle << "</style>\n</head>\n<body>\n<h1>" << Html(title) << "</h1>\n";
  o << "<p>Folder <code>" << Html(fs::absolute(dir).lexically_normal().string()) << "</code>, the output of <b>"
    << Html(c.kind == "mcms output" ? "an mcms command" : "mcms " + c.kind) << "</b>: " << files.size() << " files";
  if (!folders.empty()) o << ", " << folders.size() << " folders";
  o << ".</p>\n";
  // The answer first (issue 26): for the demo, its headline table before everything else.
  // The answer first (issue 26); an empty folder gets a page that says so.
  Answer answer;
  if (svgs.empty() && csvs.empty() && reports.empty() && inputs.empty()) {
    answer.status = "empty";
    answer.lead = "Nothing to report: " + fs::absolute(dir).lexically_normal().string() +
                  (files.empty() ? " holds no file" : " holds no result file (CSV, SVG, TXT, YAML or JSON)") +
                  ". The command that should have written it failed or has not run; its own messages say why.";
  } else {
    answer = FirstScreen(c.kind, tables, texts, svgs);
  }
  c.status = answer.status;
  o << (c.kind == "demo" && answer.status == "ok" ? answer.html : AnswerHtml(answer));

  // Sections; the table of contents is filled as they are written.
  std::ostringstream body;
  std::vector<std::pair<std::string, std::string>> toc;
  auto section = [&](const std::string& id, const std::string& heading) {
    toc.push_back({id, heading});
    body << "<h2 id=\"" << id << "\">" << Html(heading) << "</h2>\n";
  };

  // Figures: the SVG files, then plots made from tracker pose tables.
  std::ostringstream figs;
  size_t embedded = 0;  // bytes of figures in the page: bounded in all (kMaxEmbeddedBytes)
  for (const File* f : svgs) {
    if (f->size > kMaxSvgBytes) {
      figs << Note(f->name + ": " + Bytes(f->size) + ", larger than " + Bytes(kMaxSvgBytes) + "; not embedded");
      c.listed.push_back(f->name);
      continue;
    }

    const std::string svg = ReadTextFile(f->path);
    const auto open = svg.find("<svg");
    if (open == std::string::npos || svg.rfind("</svg>") == std::string::npos || svg.rfind("</svg>") < open) {
      figs << Note(f->name + ": not an SVG document (no <svg> ... </svg>); not embedded");
      c.listed.push_back(f->name);
      continue;
    }
    const std::string figure = FigureHtml(svg, f->name);
    if (embedded + figure.size() > kMaxEmbeddedBytes) {
      figs << Note(f->name + ": " + Bytes(figure.size()) + " more would take the page's figures beyond " +
                   Bytes(kMaxEmbeddedBytes) + "; not embedded (open it beside the page)");
      c.listed.push_back(f->name);
      continue;
    }
    embedded += figure.size();
    figs << figure;
    ++c.figures;
  }
  std::ostringstream track;
  for (const auto& [name, t] : tables)
    if (IsTrackerPoses(t) && !t.rows.empty()) c.figures += TrackerPlots(t, name, track);
  // ISO 9283 characteristics get their plots unless the folder has them already (the demo).
  const bool has_iso_svg =
      std::any_of(svgs.begin(), svgs.end(), [](const File* f) { return StartsWith(f->name, "iso9283_"); });
  for (const auto& [name, t] : tables)
    if (IsIso9283Characteristics(t) && !t.rows.empty() && !has_iso_svg) c.figures += Iso9283Plots(t, name, figs);
  if (!figs.str().empty() || !track.str().empty()) {
    section("figures", "Figures");
    body << figs.str();
    if (!track.str().empty()) {
      body << "<h3>Per-frame tracking</h3>\n";
      for (const auto& n : truth_notes) body << "<p>" << Html(n) << "</p>\n";
      body << track.str();
    }
  }

  if (!csvs.empty()) {
    section("tables", "Tables");
    for (const File* f : csvs) {
      const auto t = tables.find(f->name);
      const bool small = t != tables.end() && t->second.rows.size() <= options.max_table_rows;
      body << "<details" << (small ? " open" : "") << "><summary>" << Html(f->name) << " (";
      if (t != tables.end())
        body << t->second.rows.size() << " rows)";
      else
        body << Bytes(f->size) << ")";
      body << "</summary>\n";
      if (t != tables.end()) {
        body << TableHtml(t->second, options.max_table_rows);
        ++c.tables;
      } else {
        body << Note(f->name + ": not shown as a table: " + table_errors[f->name]);
        c.listed.push_back(f->name);
      }
      body << "</details>\n";
    }
  }

  // Reports: summary*.txt first, then the rest in name order.
  std::vector<const File*> ordered = reports;
  auto rank = [](const File* f) {
    const std::string n = Lower(f->name);
    return n == "summary.txt" ? 0 : n.find("summary") != std::string::npos ? 1 : 2;
  };
  std::stable_sort(ordered.begin(), ordered.end(), [&](const File* a, const File* b) { return rank(a) < rank(b); });
  if (!ordered.empty()) {
    section("reports", "Reports (text)");
    for (const File* f : ordered) {
      // A long report shows its head; the rest is one click away.
      const std::string& text = texts[f->name];
      size_t cut_at = 0, lines = 0;
      for (size_t i = 0; i < text.size() && lines < kReportHeadLines; ++i)
        if (text[i] == '\n') ++lines, cut_at = i + 1;
      const size_t total_lines = static_cast<size_t>(std::count(text.begin(), text.end(), '\n'));
      body << "<details><summary><h3>" << Html(f->name) << "</h3> (" << total_lines << " lines)</summary>\n";
      if (total_lines > kReportHeadLines + 10) {
        body << "<pre>" << Html(text.substr(0, cut_at)) << "</pre>\n<details><summary>"
             << total_lines - kReportHeadLines << " more lines</summary><pre>" << Html(text.substr(cut_at))
             << "</pre></details>\n";
      } else {
        body << "<pre>" << Html(text) << "</pre>\n";
      }
      if (cut[f->name])
        body << Note(f->name + ": cut after " + Bytes(options.max_text_bytes) + " of " + Bytes(f->size));
      body << "</details>\n";
      ++c.texts;
    }
  }

  if (!inputs.empty()) {
    section("inputs", "Inputs and models");
    for (const File* f : inputs) {
      body << "<details><summary>" << Html(f->name) << " (" << Bytes(f->size) << ")</summary>\n<pre>"
           << Html(texts[f->name]) << "</pre>\n";
      if (cut[f->name])
        body << Note(f->name + ": cut after " + Bytes(options.max_text_bytes) + " of " + Bytes(f->size));
      body << "</details>\n";
      ++c.inputs;
    }
  }

  section("files", "Files");
  body << "<ul class=\"files\">\n";
  for (const auto& f : files) body << "<li>" << Html(f.name) << " (" << Bytes(f.size) << ")</li>\n";
  for (const auto& [name, count] : folders)
    body << "<li>" << Html(name) << "/ (" << count << " files, not embedded)</li>\n";
  body << "</ul>\n";
  for (const File* f : others) c.listed.push_back(f->name);

  o << "<nav><p>";
  for (size_t i = 0; i < toc.size(); ++i)
    o << (i ? " &middot; " : "") << "<a href=\"#" << toc[i].first << "\">" << Html(toc[i].second) << "</a>";
  o << "</p></nav>\n" << body.str() << "<script>" << kScript << "</script>\n</body>\n</html>\n";
  if (contents) *contents = c;
  return o.str();
}

HtmlReportContents WriteHtmlReport(const HtmlReportOptions& options, const fs::path& output) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  // The page reads every file of the folder but earlier pages: none may be the output.
  std::vector<File> files;
  std::vector<std::pair<std::string, size_t>> folders;
  if (std::filesystem::is_directory(options.dir)) ListFolder(options.dir, &files, &folders);
  std::vector<fs::path> inputs;
  for (const File& f : files) inputs.push_back(f.path);
  RequireOutputsSpareInputs({{output, "mcms report -o"}}, inputs);
  // Inside the folder it reports, the page may only be an HTML page (which the report skips
  // as an earlier page): any other file there is part of the run (a camera model, the
  // truth), or would become part of it.
  if (!options.dir.empty() && PathWithin(ResolvedPath(output), ResolvedPath(options.dir)) &&
      Lower(output.extension().string()) != ".html")
    Throw("mcms report -o ", output.string(), " lies inside the reported folder ", options.dir.string(),
          " and is not an .html page: it would replace or join the run's files; give a .html name or a path outside");
  RequireWritableFile(output, "mcms report -o");
  // An existing page is replaced only when mcms report wrote it (its generator line, or
  // the content policy every page has had): not the user's own report.html.
  RequireOwnEarlierOutput(
      output,
      [](const std::string& head) {
        return head.find("<meta name=\"generator\" content=\"mcms report\">") != std::string::npos ||
               head.find("content=\"default-src 'none'; img-src data:;") != std::string::npos;
      },
      "mcms report -o", "a page mcms report wrote", "choose another name (-o) or move it");
  HtmlReportContents c;
  const std::string page = BuildHtmlReport(options, &c);
  WriteFileAtomically(output, [&](std::ostream& out) { out << page; });
  return c;
}

}  // namespace mcms
