// What an output folder came from and its first screen, for `mcms report`.
#include "jobs/html_report_internal.h"

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

namespace mcms::html_report_internal {

namespace fs = std::filesystem;
std::string DemoHeadline(const std::string& summary) {
  std::istringstream in(summary);
  std::string line;
  bool in_table = false;
  std::ostringstream rows, paper;
  int n = 0;
  while (std::getline(in, line)) {
    if (StartsWith(line, "Flange pose at the")) {
      in_table = true;
      continue;
    }
    if (in_table && line.empty()) in_table = false;
    if (in_table) {
      std::istringstream ls(line);
      std::vector<std::string> tok;
      for (std::string t; ls >> t;) tok.push_back(t);
      const bool counted = tok.size() >= 8 && !tok[1].empty() &&
                           tok[1].find_first_not_of("0123456789") == std::string::npos;  // "points" column
      if (counted && (tok[0] == "camera" || tok[0] == "robot" || tok[0] == "MOIFA" || tok[0] == "KF")) {
        const bool fused = tok[0] == "MOIFA" || tok[0] == "KF";
        rows << "<tr" << (fused ? " class=\"fused\"" : "") << "><td>" << Html(tok[0]) << "</td><td>" << Html(tok[3])
             << "</td><td>" << Html(tok[2]) << "</td><td>" << Html(tok[4]) << "</td><td>" << Html(tok[5]) << "</td><td>"
             << Html(tok[7]) << "</td></tr>\n";
        ++n;
      }
    }
    if (StartsWith(line, "  three-sigma position error") || StartsWith(line, "  MOIFA reduction") ||
        StartsWith(line, "  KF    reduction"))
      paper << "<li>" << Html(line.substr(2)) << "</li>\n";
  }
  if (n == 0) return "";
  std::ostringstream o;
  o << "<section id=\"answer\" class=\"answer ok\"><h2>The answer</h2>\n<p>Flange pose error at the demo's points (robot base frame), "
       "each sensor alone and fused; reduction = 1 - method's three-sigma error / the camera's, as the paper "
       "reports it.</p>\n<table class=\"headline\"><thead><tr><th>method</th><th>position 3&sigma; mm</th>"
       "<th>position RMS mm</th><th>reduction</th><th>tilt RMS deg</th><th>mean NEES</th></tr></thead><tbody>\n"
    << rows.str() << "</tbody></table>\n";
  if (!paper.str().empty()) o << "<p>Against the paper's lab experiment:</p><ul>\n" << paper.str() << "</ul>\n";
  o << "</section>\n";
  return o.str();
}

std::string DetectKind(const std::string& recorded, const std::vector<File>& files,
                       const std::map<std::string, Table>& tables, const std::map<std::string, std::string>& texts) {
  if (StartsWith(recorded, "audit ")) return "audit";
  for (const char* k : {"demo", "fov-map", "calib-rig", "iso9283", "track", "fuse", "calib-robot"})
    if (recorded == k) return recorded;
  std::set<std::string> names;
  for (const auto& f : files) names.insert(f.name);
  auto any = [&](auto pred) {
    return std::any_of(files.begin(), files.end(), [&](const File& f) { return pred(f.name); });
  };
  if (names.count("point_errors.csv") && names.count("fused_poses.csv")) return "demo";
  if (names.count("map.csv") || any([](const std::string& n) { return StartsWith(n, "heatmap_z"); })) return "fov-map";
  if (names.count("rig.yaml") && any([](const std::string& n) { return StartsWith(n, "residuals-"); }))
    return "calib-rig";
  // An audit's folder: report.txt that starts "audit (<mode>)" beside report.json (whose
  // first screen then says when the JSON is not a whole report).
  if (texts.count("report.json") && texts.count("report.txt") && StartsWith(texts.at("report.txt"), "audit ("))
    return "audit";
  for (const auto& [n, text] : texts) {
    if (text.find("# mcms calib-robot report") != std::string::npos) return "calib-robot";
    if (text.find("\"effects\"") != std::string::npos && text.find("\"nominal\"") != std::string::npos) return "audit";
    if (text.find("camera  observations  chi2/dof") != std::string::npos)
      return "audit";  // `mcms audit cameras` > FILE
  }
  for (const auto& [n, t] : tables) {
    if (IsIso9283Characteristics(t) || (t.Column("pose") >= 0 && t.Column("cycle") >= 0)) return "iso9283";
    if (IsTrackerPoses(t)) return "track";
    if (IsFusedPoses(t)) return "fuse";
  }
  return "mcms output";
}


std::string AnswerHtml(const Answer& a) {
  if (a.lead.empty() && a.html.empty()) return "";
  return "<section id=\"answer\" class=\"answer " + a.status + "\"><h2>The answer</h2>\n<p class=\"lead\">" +
         Html(a.lead) + "</p>\n" + a.html + "</section>\n";
}

std::string HeadlineTable(const std::vector<std::string>& head, const std::vector<std::vector<std::string>>& rows) {
  std::ostringstream o;
  o << "<table class=\"headline\"><thead><tr>";
  for (const auto& h : head) o << "<th>" << Html(h) << "</th>";
  o << "</tr></thead><tbody>\n";
  for (const auto& r : rows) {
    o << "<tr>";
    for (const auto& c : r) o << "<td>" << Html(c) << "</td>";
    o << "</tr>\n";
  }
  o << "</tbody></table>\n";
  return o.str();
}

std::string Fixed(double v, int digits) {
  char buf[48];
  std::snprintf(buf, sizeof(buf), "%.*f", digits, v);
  return buf;
}

// The lines of a text that start with one of `prefixes` (leading blanks ignored), in order.
std::vector<std::string> LinesStartingWith(const std::string& text, const std::vector<std::string>& prefixes) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    const auto b = line.find_first_not_of(" \t");
    if (b == std::string::npos) continue;
    for (const auto& p : prefixes)
      if (line.compare(b, p.size(), p) == 0) {
        out.push_back(line.substr(b));
        break;
      }
  }
  return out;
}

// A track: frames ok / degraded / lost per pose table and, against a truth, the error and
// the NEES (the columns AddTruthColumns or `mcms track --truth` wrote).
Answer TrackAnswer(const std::map<std::string, Table>& tables) {
  Answer a;
  std::vector<std::vector<std::string>> rows;
  bool truth = false;
  for (const auto& [name, t] : tables) {
    if (!IsTrackerPoses(t)) continue;
    const int cs = t.Column("status");
    size_t ok = 0, degraded = 0, lost = 0;
    for (const auto& r : t.rows) (r[cs] == "ok" ? ok : r[cs] == "lost" ? lost : degraded) += 1;
    const size_t n = t.rows.size();
    // Position error: the three axes (report's truth columns) or err_pos_mm (track --truth).
    const int ex = t.Column("err_x_mm"), ey = t.Column("err_y_mm"), ez = t.Column("err_z_mm"),
              ep = t.Column("err_pos_mm"), cn = t.Column("nees");
    double sq = 0, nees = 0;
    size_t ne = 0, nn = 0, inside = 0;
    const auto [lo, hi] = ChiSquareBand95(6);
    for (size_t r = 0; r < n; ++r) {
      if (ex >= 0 && ey >= 0 && ez >= 0) {
        const auto x = t.Value(r, ex), y = t.Value(r, ey), z = t.Value(r, ez);
        if (x && y && z) sq += *x * *x + *y * *y + *z * *z, ++ne;
      } else if (const auto e = t.Value(r, ep)) {
        sq += *e * *e, ++ne;
      }
      if (const auto v = t.Value(r, cn)) nees += *v, ++nn, inside += *v >= lo && *v <= hi;
    }
    truth = truth || ne > 0;
    rows.push_back({name, std::to_string(n), std::to_string(ok), std::to_string(degraded), std::to_string(lost),
                    ne ? Fixed(std::sqrt(sq / static_cast<double>(ne)), 4) : "",
                    nn ? Fixed(nees / static_cast<double>(nn), 2) : "",
                    nn ? std::to_string(100 * inside / nn) + " %" : ""});
    if (a.lead.empty()) {
      a.lead = std::to_string(n) + " frames: " + std::to_string(ok) + " ok, " + std::to_string(degraded) +
               " degraded, " + std::to_string(lost) + " lost";
      if (ne) a.lead += "; position error RMS " + Fixed(std::sqrt(sq / static_cast<double>(ne)), 4) + " mm against the truth";
      if (nn)
        a.lead += ", mean NEES " + Fixed(nees / static_cast<double>(nn), 2) + " (6 when the reported covariance is honest)";
      a.lead += ".";
      if (n == 0) a.status = "failed", a.lead = name + " holds no frame: the tracker stopped before its first frame.";
      else if (ok + degraded == 0) a.status = "failed", a.lead = "No frame tracked: all " + std::to_string(n) + " frames of " + name + " are lost.";
      for (const auto& c : t.comments)
        if (c.find("pose-fit residuals") != std::string::npos) a.html += "<p>" + Html(c.substr(c.find_first_not_of("# "))) + "</p>\n";
    }
  }
  std::vector<std::string> head{"poses", "frames", "ok", "degraded", "lost"};
  if (truth) head.insert(head.end(), {"position error RMS mm", "mean NEES", "NEES inside 95 % band"});
  for (auto& r : rows) r.resize(head.size());
  a.html = HeadlineTable(head, rows) + a.html;
  return a;
}

// Size +- sigma of an audit effect's parameters (SI units); many parameters (the geometry)
// are summarised by their count and the one furthest from zero in sigmas.
std::string EffectSize(const nlohmann::json& e) {
  const auto& p = e.value("parameters", nlohmann::json::object());
  const auto& s = e.value("sigma", nlohmann::json::object());
  std::vector<std::string> parts;
  std::string widest;
  double widest_z = -1;
  size_t numeric = 0;
  for (auto it = p.begin(); it != p.end(); ++it) {
    if (!it.value().is_number()) {
      parts.push_back(it.key() + " " + it.value().dump());
      continue;
    }
    ++numeric;
    const double v = it.value().get<double>();
    const double sg = s.contains(it.key()) && s[it.key()].is_number() ? s[it.key()].get<double>() : NAN;
    const std::string text = it.key() + " = " + Num(v) + (std::isfinite(sg) ? " ± " + Num(sg) : "");
    parts.push_back(text);
    const double z = std::isfinite(sg) && sg > 0 ? std::abs(v) / sg : 0;
    if (z > widest_z) widest_z = z, widest = text;
  }
  if (numeric > 3) return std::to_string(numeric) + " parameters; furthest from zero: " + widest;
  std::string o;
  for (size_t i = 0; i < parts.size(); ++i) o += (i ? ", " : "") + parts[i];
  return o;
}

// The plot that shows effect k (1-based) of an audit: the robot audit's plots/effect<k>.svg,
// else a plot named after where the effect sits (cam2 -> plots/cam2.svg), else none.
const File* PlotOfEffect(const std::vector<const File*>& svgs, size_t k, std::string where) {
  where.erase(std::remove(where.begin(), where.end(), ' '), where.end());
  for (const File* f : svgs)
    if (f->name == "plots/effect" + std::to_string(k) + ".svg") return f;
  for (const File* f : svgs)
    if (!where.empty() && f->name.find(where) != std::string::npos) return f;
  return nullptr;
}

// An audit (cameras, robot, fusion, lens): from report.json, each named effect with its
// size, held-out gain and the plot that shows it; or that the model explains the data; or
// which tests failed with no catalog effect to explain them.
Answer AuditAnswer(const std::map<std::string, std::string>& texts, const std::vector<const File*>& svgs) {
  Answer a;
  const auto it = texts.find("report.json");
  if (it == texts.end()) return a;
  const auto j = nlohmann::json::parse(it->second, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("effects")) {
    a.status = "failed";
    a.lead = "report.json is not an audit report (no \"effects\"): the audit did not finish?";
    return a;
  }
  const std::string mode = j.value("mode", std::string("?")), unit = j.value("rms_unit", std::string());
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> names;
  const File* figure = nullptr;
  size_t k = 0;
  for (const auto& e : j["effects"]) {
    ++k;
    const std::string name = e.value("name", std::string("?")), where = e.value("where", std::string());
    const std::string u = e.value("rms_unit", unit);
    auto num = [&](const char* key) { return e.contains(key) && e[key].is_number() ? Num(e[key].get<double>()) : std::string("-"); };
    rows.push_back({name, where, EffectSize(e), num("heldout_rms_before") + " → " + num("heldout_rms_after") + " " + u,
                    num("heldout_loglik_gain")});
    names.push_back(name + (where.empty() ? "" : " at " + where));
    if (!figure) figure = PlotOfEffect(svgs, k, where);
  }
  const auto& tests = j.value("tests", nlohmann::json::array());
  std::vector<std::string> failed;
  for (const auto& t : tests)
    if (t.value("failed", false)) failed.push_back(t.value("name", std::string("?")));
  const std::string chi2 = j.contains("nominal") && j["nominal"].contains("chi2_per_dof") && j["nominal"]["chi2_per_dof"].is_number()
                               ? Fixed(j["nominal"]["chi2_per_dof"].get<double>(), 3)
                               : "?";
  if (!rows.empty()) {
    a.status = "findings";
    a.lead = "The " + mode + " audit names " + std::to_string(rows.size()) + (rows.size() == 1 ? " effect: " : " effects: ");
    for (size_t i = 0; i < names.size(); ++i) a.lead += (i ? ", " : "") + names[i];
    a.lead += ".";
    a.html += HeadlineTable({"effect", "where", "size ± 1 sigma (SI: m, rad)", "held-out RMS before → after",
                             "held-out log-likelihood gain (nats)"},
                            rows);
  } else if (j.value("clean", false)) {
    a.lead = "No effect found: the nominal model explains the " + mode + " data within its noise (chi2/dof " + chi2 +
             ", " + std::to_string(tests.size()) + " tests, none failed).";
  } else {
    a.status = "findings";
    a.lead = "The nominal model does not explain the " + mode + " data (chi2/dof " + chi2 + "; " +
             std::to_string(failed.size()) + " of " + std::to_string(tests.size()) +
             " tests failed), and no effect of the catalog explains it.";
  }
  if (!failed.empty()) {
    a.html += "<p>Tests of the nominal model that failed:</p><ul>\n";
    for (const auto& f : failed) a.html += "<li>" + Html(f) + "</li>\n";
    a.html += "</ul>\n";
  }
  for (const auto& g : j.value("undecided", nlohmann::json::array())) {
    std::string group;
    for (const auto& x : g) group += (group.empty() ? "" : " or ") + (x.is_string() ? x.get<std::string>() : x.dump());
    a.html += "<p>Undecided (the data cannot tell them apart): " + Html(group) + "; next_poses.csv, where written, "
              "lists the poses that would.</p>\n";
  }
  if (figure) a.html += FigureHtml(ReadTextFile(figure->path), figure->name);
  return a;
}

// fov-map: region.txt's best, worst and the share below the threshold, beside sigma against
// distance.
Answer FovMapAnswer(const std::map<std::string, std::string>& texts, const std::vector<const File*>& svgs) {
  Answer a;
  const auto it = texts.find("region.txt");
  if (it != texts.end()) {
    const auto lines = LinesStartingWith(it->second, {"grid ", "best ", "worst ", "sigma_d <"});
    for (const auto& l : lines)
      if (StartsWith(l, "sigma_d <")) a.lead = "The rig measures with " + l + ".";
    if (a.lead.empty() && !lines.empty()) a.lead = lines.front();
    if (!lines.empty()) {
      a.html += "<ul>\n";
      for (const auto& l : lines) a.html += "<li>" + Html(l) + "</li>\n";
      a.html += "</ul>\n";
    }
  }
  for (const File* f : svgs)
    if (f->name == "sigma_vs_distance.svg" || f->name == "measured_sigma.svg") {
      a.html += FigureHtml(ReadTextFile(f->path), f->name);
      break;
    }
  if (a.lead.empty() && !a.html.empty()) a.lead = "The rig's precision over its measuring volume:";
  return a;
}

// calib-rig: summary.txt's fit per camera, the residual against the views' own noise floor,
// and the first camera's residual plot.
Answer CalibRigAnswer(const std::map<std::string, std::string>& texts, const std::vector<const File*>& svgs) {
  Answer a;
  const auto it = texts.find("summary.txt");
  if (it == texts.end()) {
    a.status = "failed";
    a.lead = "summary.txt is missing: the calibration did not finish (calib-rig writes it with rig.yaml).";
  } else {
    std::vector<std::vector<std::string>> rows;
    std::istringstream in(it->second);
    for (std::string l; std::getline(in, l);) {
      // "cam0: 13 views, 700/702 points, RMS 0.21 px per coordinate (0.3 px per point), max 1.2 px"
      const auto colon = l.find(": "), views = l.find(" views, "), rms = l.find(", RMS "), mx = l.find(", max ");
      if (l.empty() || l[0] == ' ' || colon == std::string::npos || views == std::string::npos ||
          rms == std::string::npos || mx == std::string::npos)
        continue;
      rows.push_back({l.substr(0, colon), l.substr(colon + 2, views - colon - 2),
                      l.substr(views + 8, l.find(" points") - views - 8), l.substr(rms + 6, l.find(" px", rms) - rms - 6),
                      l.substr(mx + 6, l.find(" px", mx) - mx - 6)});
    }
    for (const auto& l : LinesStartingWith(it->second, {"residual against the views' own noise floor"})) a.lead = l;
    if (a.lead.empty()) a.lead = "Camera calibration:";
    for (const auto& l : LinesStartingWith(it->second, {"WARNING", "last solve"}))
      if (StartsWith(l, "WARNING") || l.find("NOT CONVERGED") != std::string::npos)
        a.status = "findings", a.html += "<p class=\"note\">" + Html(l) + "</p>\n";
    a.html = HeadlineTable({"camera", "views", "points (inliers/all)", "RMS px per coordinate", "max px"}, rows) + a.html;
  }
  for (const File* f : svgs)
    if (StartsWith(f->name, "residuals-")) {
      a.html += FigureHtml(ReadTextFile(f->path), f->name);
      break;
    }
  return a;
}

// calib-robot: its report's residual lines (before, nominal registered, calibrated, held
// out) and the error-per-measurement plot.
Answer CalibRobotAnswer(const std::map<std::string, std::string>& texts, const std::vector<const File*>& svgs) {
  Answer a;
  for (const auto& [name, text] : texts) {
    if (text.find("# mcms calib-robot report") == std::string::npos) continue;
    std::vector<std::vector<std::string>> rows;
    for (const auto& l : LinesStartingWith(text, {"residuals, ", "held out ("})) {
      const auto colon = l.find(':');
      rows.push_back({l.substr(0, colon), colon == std::string::npos ? "" : l.substr(l.find_first_not_of(' ', colon + 1))});
    }
    for (const auto& l : LinesStartingWith(text, {"solver:"})) {
      a.lead = "Robot calibration from " + name + ": " + l.substr(8) + ".";
      if (l.find("did NOT converge") != std::string::npos) a.status = "failed";
    }
    a.html += HeadlineTable({"positions and orientations", "error"}, rows);
    break;
  }
  for (const File* f : svgs)
    if (f->name.find("-joints") == std::string::npos) {
      a.html += FigureHtml(ReadTextFile(f->path), f->name);
      break;
    }
  return a;
}

// iso9283: AP and RP per condition, the mean and the worst of the poses.
Answer Iso9283Answer(const std::map<std::string, Table>& tables) {
  Answer a;
  for (const auto& [name, t] : tables) {
    if (!IsIso9283Characteristics(t)) continue;
    const int cc = t.Column("condition"), ca = t.Column("AP_mm"), cr = t.Column("RP_mm");
    std::vector<std::string> order;
    std::map<std::string, std::vector<std::pair<double, double>>> by;
    for (size_t r = 0; r < t.rows.size(); ++r) {
      const std::string c = cc >= 0 ? t.rows[r][cc] : "measured";
      if (!by.count(c)) order.push_back(c);
      by[c].push_back({t.Value(r, ca).value_or(NAN), t.Value(r, cr).value_or(NAN)});
    }
    std::vector<std::vector<std::string>> rows;
    for (const auto& c : order) {
      double ap = 0, apmax = 0, rp = 0, rpmax = 0;
      for (const auto& [x, y] : by[c]) ap += x, apmax = std::max(apmax, x), rp += y, rpmax = std::max(rpmax, y);
      const double n = static_cast<double>(by[c].size());
      rows.push_back({c, std::to_string(by[c].size()), Fixed(ap / n, 4), Fixed(apmax, 4), Fixed(rp / n, 4), Fixed(rpmax, 4)});
    }
    a.lead = "ISO 9283 pose accuracy AP and repeatability RP from " + name + ", per condition (mm):";
    a.html = HeadlineTable({"condition", "poses", "AP mean", "AP worst", "RP mean", "RP worst"}, rows);
    break;
  }
  return a;
}

// fuse: fused rows per method, how many had a flagged or left-out sensor, the median
// predicted position sigma.
Answer FuseAnswer(const std::map<std::string, Table>& tables) {
  Answer a;
  for (const auto& [name, t] : tables) {
    if (!IsFusedPoses(t)) continue;
    const int cm = t.Column("method"), cf = t.Column("flagged"), ce = t.Column("excluded");
    const int cx = t.Column("cov_px_px"), cy = t.Column("cov_py_py"), cz = t.Column("cov_pz_pz");
    std::vector<std::string> order;
    std::map<std::string, std::vector<size_t>> rows_of;
    for (size_t r = 0; r < t.rows.size(); ++r) {
      if (!rows_of.count(t.rows[r][cm])) order.push_back(t.rows[r][cm]);
      rows_of[t.rows[r][cm]].push_back(r);
    }
    std::vector<std::vector<std::string>> rows;
    size_t flagged_all = 0;
    for (const auto& m : order) {
      size_t flagged = 0, excluded = 0;
      std::vector<double> sigma;
      for (size_t r : rows_of[m]) {
        flagged += !t.rows[r][cf].empty();
        excluded += ce >= 0 && !t.rows[r][ce].empty();
        const auto x = t.Value(r, cx), y = t.Value(r, cy), z = t.Value(r, cz);
        if (x && y && z) sigma.push_back(1e3 * std::sqrt(*x + *y + *z));
      }
      flagged_all += flagged;
      std::string med;
      if (!sigma.empty()) med = Fixed(SelectedMedian(sigma), 4);
      rows.push_back({m, std::to_string(rows_of[m].size()), std::to_string(flagged), std::to_string(excluded), med});
    }
    a.lead = name + ": " + std::to_string(t.rows.size()) + " fused poses by " + std::to_string(order.size()) +
             (order.size() == 1 ? " method" : " methods") + "; " + std::to_string(flagged_all) +
             " with a sensor flagged as inconsistent.";
    if (t.rows.empty()) a.status = "failed", a.lead = name + " holds no fused pose.";
    else if (flagged_all) a.status = "findings";
    a.html = HeadlineTable({"method", "rows", "flagged", "sensor left out", "median position sigma mm"}, rows);
    break;
  }
  return a;
}

// The first screen of a page: by what the folder came from; a demo without its summary,
// a tracker that tracked nothing, an audit that did not finish say so.
Answer FirstScreen(const std::string& kind, const std::map<std::string, Table>& tables,
                   const std::map<std::string, std::string>& texts, const std::vector<const File*>& svgs) {
  Answer a;
  if (kind == "demo") {
    const auto it = texts.find("summary.txt");
    a.html = it == texts.end() ? "" : DemoHeadline(it->second);
    if (a.html.empty())
      a.status = "failed", a.lead = "The demo did not finish: summary.txt, written last, is missing or holds no result table.";
    return a;
  }
  if (kind == "track") return TrackAnswer(tables);
  if (kind == "audit") a = AuditAnswer(texts, svgs);
  if (kind == "fov-map") a = FovMapAnswer(texts, svgs);
  if (kind == "calib-rig") a = CalibRigAnswer(texts, svgs);
  if (kind == "calib-robot") a = CalibRobotAnswer(texts, svgs);
  if (kind == "iso9283") a = Iso9283Answer(tables);
  if (kind == "fuse") a = FuseAnswer(tables);
  if (a.lead.empty() && a.html.empty())
    a.lead = "No known command's result was recognised in this folder; its files follow.";
  return a;
}

}  // namespace mcms::html_report_internal
