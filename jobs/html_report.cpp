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

namespace {

constexpr size_t kMaxSvgBytes = size_t{8} << 20;  // a larger SVG is listed, not embedded
constexpr size_t kReportHeadLines = 60;           // lines of a long report shown before "more"
constexpr size_t kMaxSortableRows = 2000;         // a longer table shows its first and last rows

// Why `s` is not UTF-8 text ("" when it is): a NUL byte, a control character other than
// tab, line feed, carriage return and form feed, or a byte sequence that is not UTF-8 (a
// sequence cut at the end of a bounded read is allowed).
// The length of the UTF-8 sequence at s[i] (1 for ASCII); 0 where it is not UTF-8, -1 where
// a valid start is cut by the end of `s`.
int Utf8Length(const std::string& s, size_t i) {
  const auto c = static_cast<unsigned char>(s[i]);
  if (c < 0x80) return 1;
  int len = 0;  // the sequence's length by its lead byte
  if (c >= 0xc2 && c <= 0xdf) len = 2;
  else if (c >= 0xe0 && c <= 0xef) len = 3;
  else if (c >= 0xf0 && c <= 0xf4) len = 4;
  if (len == 0) return 0;
  for (int k = 1; k < len; ++k) {
    if (i + k >= s.size()) return -1;
    if ((static_cast<unsigned char>(s[i + k]) & 0xc0) != 0x80) return 0;
  }
  return len;
}

bool ControlCharacter(unsigned char c) { return c < 0x20 && c != '\t' && c != '\n' && c != '\r' && c != '\f'; }

std::string NotText(const std::string& s) {
  for (size_t i = 0; i < s.size();) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c == 0) return "a NUL byte at " + std::to_string(i);
    if (ControlCharacter(c)) return "control character " + std::to_string(c) + " at " + std::to_string(i);
    const int len = Utf8Length(s, i);
    if (len < 0) return "";
    if (len == 0) return "a byte that is not UTF-8 at " + std::to_string(i);
    i += len;
  }
  return "";
}

// `s` escaped for HTML; a byte that is not UTF-8 or a control character (a file name is any
// bytes but '/' and NUL) becomes U+FFFD, so the page stays UTF-8.
std::string Html(const std::string& s) {
  std::string o;
  o.reserve(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    const int len = Utf8Length(s, i);
    if (len <= 0 || (len == 1 && ControlCharacter(static_cast<unsigned char>(c)))) {
      o += "\xef\xbf\xbd";
      continue;
    }
    if (len > 1) {
      o.append(s, i, static_cast<size_t>(len));
      i += static_cast<size_t>(len) - 1;
      continue;
    }
    switch (c) {
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '&':
        o += "&amp;";
        break;
      case '"':
        o += "&quot;";
        break;
      case '\'':
        o += "&#39;";
        break;
      default:
        o += c;
    }
  }
  return o;
}

std::string Base64(const std::string& in) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string o;
  o.reserve((in.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(in[i]) << 16) | (static_cast<unsigned char>(in[i + 1]) << 8) |
                       static_cast<unsigned char>(in[i + 2]);
    o += t[(v >> 18) & 63], o += t[(v >> 12) & 63], o += t[(v >> 6) & 63], o += t[v & 63];
  }
  if (i + 1 == in.size()) {
    const unsigned v = static_cast<unsigned char>(in[i]) << 16;
    o += t[(v >> 18) & 63], o += t[(v >> 12) & 63], o += "==";
  } else if (i + 2 == in.size()) {
    const unsigned v = (static_cast<unsigned char>(in[i]) << 16) | (static_cast<unsigned char>(in[i + 1]) << 8);
    o += t[(v >> 18) & 63], o += t[(v >> 12) & 63], o += t[(v >> 6) & 63], o += '=';
  }
  return o;
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool StartsWith(const std::string& s, const std::string& p) {
  return s.compare(0, p.size(), p) == 0;
}

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

std::string Bytes(uintmax_t n) {
  char buf[32];
  if (n < 10000)
    std::snprintf(buf, sizeof(buf), "%ju B", n);
  else if (n < 10000000)
    std::snprintf(buf, sizeof(buf), "%.0f kB", n / 1e3);
  else
    std::snprintf(buf, sizeof(buf), "%.0f MB", n / 1e6);
  return buf;
}

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
Table ReadTable(const fs::path& path, std::string* error) {
  Table t;
  try {
    CsvTable c = ReadCsv(path);
    t.comments = std::move(c.comments);
    t.header = std::move(c.header);
    t.rows = std::move(c.rows);
  } catch (const InputError& e) {
    // The page names the file already: the reader's message from its line on.
    std::string m = e.what();
    if (m.rfind(path.string(), 0) == 0) m = m.substr(path.string().size());
    *error = m.substr(std::min(m.size(), m.find_first_not_of(": ")));
  }
  return t;
}

struct File {
  fs::path path;
  std::string name;  // relative to the report folder
  uintmax_t size = 0;
  bool link = false;  // a symbolic link: listed, never read
};

std::string FigureHtml(const std::string& svg, const std::string& caption) {
  return "<figure><img class=\"figure\" alt=\"" + Html(caption) + "\" src=\"data:image/svg+xml;base64," + Base64(svg) +
         "\"><figcaption>" + Html(caption) + "</figcaption></figure>\n";
}

std::string Note(const std::string& s) {
  return "<p class=\"note\">" + Html(s) + "</p>\n";
}

// Rows of a table as HTML (all columns; the container scrolls sideways when wide).
void TableRows(std::ostringstream& o, const Table& t, size_t begin, size_t end) {
  for (size_t r = begin; r < end; ++r) {
    o << "<tr>";
    for (size_t c = 0; c < t.rows[r].size(); ++c) {
      // Numbers to 6 significant digits (the file keeps them all); text as it is.
      const auto v = t.Value(r, static_cast<int>(c));
      o << "<td>" << (v && t.rows[r][c].size() > 8 ? Num(*v) : Html(t.rows[r][c])) << "</td>";
    }
    o << "</tr>\n";
  }
}

std::string TableHtml(const Table& t, size_t max_rows) {
  std::ostringstream o;
  for (const auto& c : t.comments) o << "<div class=\"comment\">" << Html(c) << "</div>\n";
  const size_t n = t.rows.size();
  if (n > max_rows) {
    // Per-column statistics.
    o << "<p>" << n << " rows, " << t.header.size() << " columns; per column:</p>\n<div class=\"scroll\"><table>\n"
      << "<tr><th>column</th><th>values</th><th>min</th><th>median</th><th>max</th><th>mean</th><th>text values "
         "(count)</th></tr>\n";
    for (size_t c = 0; c < t.header.size(); ++c) {
      std::vector<double> v;
      std::map<std::string, size_t> text;
      size_t empty = 0;
      for (size_t r = 0; r < n; ++r) {
        if (auto x = t.Value(r, static_cast<int>(c)))
          v.push_back(*x);
        else if (t.rows[r][c].empty())
          ++empty;
        else
          ++text[t.rows[r][c]];
      }
      o << "<tr><td>" << Html(t.header[c]) << "</td><td>" << v.size() << " numbers";
      if (empty) o << ", " << empty << " empty";
      o << "</td>";
      if (!v.empty()) {
        double sum = 0;
        for (double x : v) sum += x;
        std::vector<double> s = v;
        const double med = SelectedMedian(s);
        o << "<td>" << Num(*std::min_element(v.begin(), v.end())) << "</td><td>" << Num(med) << "</td><td>"
          << Num(*std::max_element(v.begin(), v.end())) << "</td><td>" << Num(sum / static_cast<double>(v.size()))
          << "</td>";
      } else {
        o << "<td></td><td></td><td></td><td></td>";
      }
      o << "<td>";
      std::vector<std::pair<size_t, std::string>> by_count;
      for (const auto& [k, m] : text) by_count.push_back({m, k});
      std::sort(by_count.begin(), by_count.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
      for (size_t i = 0; i < by_count.size() && i < 6; ++i)
        o << (i ? ", " : "") << Html(by_count[i].second.empty() ? "(empty)" : by_count[i].second) << " ("
          << by_count[i].first << ")";
      if (by_count.size() > 6) o << ", ... (" << by_count.size() << " distinct)";
      o << "</td></tr>\n";
    }
    o << "</table></div>\n";
    if (n <= kMaxSortableRows)
      o << "<details><summary>all " << n << " rows (a click on a column's header sorts by it)</summary>\n";
    else
      o << "<p>First and last rows:</p>\n";
  }
  o << "<div class=\"scroll" << (n > max_rows ? " tall" : "") << "\"><table class=\"sortable\">\n<thead><tr>";
  for (const auto& h : t.header) o << "<th>" << Html(h) << "</th>";
  o << "</tr></thead>\n<tbody>\n";
  if (n <= kMaxSortableRows) {
    TableRows(o, t, 0, n);
  } else {
    const size_t k = std::max<size_t>(1, max_rows / 2);
    TableRows(o, t, 0, k);
    o << "<tr><td class=\"gap\" colspan=\"" << t.header.size() << "\">... " << n - 2 * k << " rows ...</td></tr>\n";
    TableRows(o, t, n - k, n);
  }
  o << "</tbody></table></div>\n";
  if (n > max_rows && n <= kMaxSortableRows) o << "</details>\n";
  return o.str();
}

bool IsTrackerPoses(const Table& t) {
  return t.Column("frame") >= 0 && t.Column("time_s") >= 0 && t.Column("status") >= 0 && t.Column("x_m") >= 0;
}

// 95 % two-sided band of a chi-square variable with k degrees of freedom.
std::pair<double, double> ChiSquareBand95(int k) {
  return ChiSquareBand(k, 0.95);
}

// Adds err_x_mm, err_y_mm, err_z_mm, err_rot_mdeg and nees columns to a tracker pose table
// from a truth pose table (frame,x_m,y_m,z_m,qw,qx,qy,qz: T_rig_target, what `mcms render`
// writes to truth/poses.csv), matched by frame. The error is the estimate's against the
// truth (core/statistics.h PoseError: BoxMinus(T_est, T_true), the [dtheta; dp] layout of
// the covariance), NEES = e^T Cov^-1 e (PoseNees). Returns a summary line,
// or the reason nothing was added.
std::string AddTruthColumns(Table& t, const Table& truth) {
  const char* pose_cols[] = {"x_m", "y_m", "z_m", "qw", "qx", "qy", "qz"};
  int tc[7], ec[7];
  for (int i = 0; i < 7; ++i) {
    tc[i] = truth.Column(pose_cols[i]);
    ec[i] = t.Column(pose_cols[i]);
    if (tc[i] < 0) return std::string("the truth file has no ") + pose_cols[i] + " column";
  }
  const int tf = truth.Column("frame"), ef = t.Column("frame");
  if (tf < 0) return "the truth file has no frame column";
  const char* axes[] = {"rx", "ry", "rz", "px", "py", "pz"};
  int cov[6][6];
  bool have_cov = true;
  for (int a = 0; a < 6; ++a)
    for (int b = 0; b < 6; ++b) {
      cov[a][b] = t.Column(std::string("cov_") + axes[a] + "_" + axes[b]);
      have_cov = have_cov && cov[a][b] >= 0;
    }
  // A pose: seven finite values whose quaternion is a unit one (within 1e-3: a pose file
  // rounds, it does not invent a norm of 5).
  auto pose_of = [](const Table& tab, size_t r, const int* c) -> std::optional<Pose> {
    double v[7];
    for (int i = 0; i < 7; ++i) {
      const auto x = tab.Value(r, c[i]);
      if (!x || !std::isfinite(*x)) return std::nullopt;
      v[i] = *x;
    }
    const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
    if (!(std::abs(q.norm() - 1.0) <= 1e-3)) return std::nullopt;
    return Pose::FromQuaternion(q.normalized(), Vec3(v[0], v[1], v[2]));
  };
  std::map<long long, Pose> truth_by_frame;
  for (size_t r = 0; r < truth.rows.size(); ++r)
    if (const auto f = truth.Value(r, tf))
      if (const auto T = pose_of(truth, r, tc)) truth_by_frame[std::llround(*f)] = *T;
  for (const char* h : {"err_x_mm", "err_y_mm", "err_z_mm", "err_rot_mdeg", "nees"}) t.header.push_back(h);
  size_t matched = 0, with_nees = 0, inside = 0, bad_pose = 0, bad_cov = 0;
  double sum_nees = 0, sum_sq_mm = 0;
  const auto [lo, hi] = ChiSquareBand95(6);
  for (size_t r = 0; r < t.rows.size(); ++r) {
    std::string cells[5];
    const auto f = t.Value(r, ef);
    const auto est = pose_of(t, r, ec);
    const auto tr = f ? truth_by_frame.find(std::llround(*f)) : truth_by_frame.end();
    bool given = f.has_value();  // a pose written (a lost frame's cells are empty)
    for (int i = 0; i < 7; ++i)
      given = given && ec[i] >= 0 && static_cast<size_t>(ec[i]) < t.rows[r].size() && !t.rows[r][ec[i]].empty();
    bad_pose += !est && given;
    if (est && tr != truth_by_frame.end()) {
      const Vec6 e = PoseErrorVector(*est, tr->second);
      ++matched;
      sum_sq_mm += 1e6 * e.tail<3>().squaredNorm();
      for (int a = 0; a < 3; ++a) cells[a] = Num(1e3 * e[3 + a]);
      cells[3] = Num(e.head<3>().norm() * 180.0 / std::numbers::pi * 1e3);
      if (have_cov) {
        Mat6 C;
        bool ok = true;
        for (int a = 0; a < 6; ++a)
          for (int b = 0; b < 6; ++b) {
            const auto v = t.Value(r, cov[a][b]);
            ok = ok && v.has_value();
            C(a, b) = v.value_or(0.0);
          }
        // A covariance: finite, symmetric, positive definite, no standard deviation above
        // 100 (m or rad): anything else is not an estimate's uncertainty.
        ok = ok && C.allFinite() && (C - C.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * C.cwiseAbs().maxCoeff() &&
             C.diagonal().maxCoeff() <= 1e4;
        Eigen::LDLT<Mat6> ldlt(C);
        ok = ok && ldlt.info() == Eigen::Success && ldlt.isPositive() && (ldlt.vectorD().array() > 0).all();
        bad_cov += !ok;
        if (ok) {
          const double nees = PoseNees(*est, tr->second, C);
          cells[4] = Num(nees);
          ++with_nees;
          sum_nees += nees;
          inside += nees >= lo && nees <= hi;
        }
      }
    }
    for (auto& c : cells) t.rows[r].push_back(c);
  }
  std::ostringstream o;
  o << "against the truth (matched by frame): " << matched << " of " << t.rows.size() << " frames";
  if (matched) o << ", position error RMS " << Num(std::sqrt(sum_sq_mm / static_cast<double>(matched))) << " mm";
  if (with_nees)
    o << ", mean NEES " << Num(sum_nees / static_cast<double>(with_nees)) << " (6 for a consistent covariance), "
      << inside << " of " << with_nees << " frames inside the 95 % band [" << lo << ", " << hi << "]";
  if (bad_pose)
    o << "; " << bad_pose << " frame(s) left out: their pose is not seven finite numbers with a unit quaternion";
  if (bad_cov)
    o << "; " << bad_cov << " frame(s) without a NEES: their covariance is not finite, symmetric and positive "
      << "definite with standard deviations below 100";
  return o.str();
}

// Per-frame plots of a tracker pose CSV; figures appended to `out`, count returned.
size_t TrackerPlots(const Table& t, const std::string& name, std::ostringstream& out) {
  const char* colors[] = {"#2ca02c", "#ff7f0e", "#d62728", "#9467bd", "#8c564b", "#1f77b4"};
  const int ct = t.Column("time_s"), cs = t.Column("status"), cb = t.Column("balls");
  const size_t n = t.rows.size();
  std::vector<double> time(n);
  for (size_t r = 0; r < n; ++r) time[r] = t.Value(r, ct).value_or(NAN);
  size_t figures = 0;
  auto emit = [&](const Plot& p, const std::string& caption) {
    out << FigureHtml(p.ToSvg(900, 360), name + ": " + caption);
    ++figures;
  };
  // Status and balls per frame.
  {
    Plot p{"Per-frame status: balls identified in each frame", "time (s)", "balls identified", {}};
    std::map<std::string, size_t> index;
    for (size_t r = 0; r < n; ++r) {
      const std::string& s = t.rows[r][cs];
      if (!index.count(s)) {
        index[s] = p.series.size();
        p.series.push_back(PlotSeries{s, {}, {}, colors[p.series.size() % 6], true});
      }
      auto& ser = p.series[index[s]];
      ser.x.push_back(time[r]);
      ser.y.push_back(cb >= 0 ? t.Value(r, cb).value_or(0.0) : 0.0);
    }
    for (auto& s : p.series) s.label += " (" + std::to_string(s.x.size()) + " frames)";
    emit(p, "status per frame");
  }
  // Position.
  {
    Plot p{"Tracked position of the target (rig frame)", "time (s)", "position (mm)", {}};
    const char* axes[] = {"x_m", "y_m", "z_m"};
    for (int a = 0; a < 3; ++a) {
      PlotSeries s{std::string(1, "xyz"[a]), {}, {}, colors[(a + 3) % 6], false};
      const int c = t.Column(axes[a]);
      for (size_t r = 0; r < n; ++r) s.x.push_back(time[r]), s.y.push_back(t.Value(r, c).value_or(NAN) * 1e3);
      p.series.push_back(s);
    }
    emit(p, "position per frame");
  }
  // Predicted sigma of the position, and the reprojection RMS.
  const int cxx = t.Column("cov_px_px"), cyy = t.Column("cov_py_py"), czz = t.Column("cov_pz_pz");
  if (cxx >= 0 && cyy >= 0 && czz >= 0) {
    Plot p{"Predicted position sigma per frame (from the 6x6 covariance)", "time (s)", "sigma (mm)", {}};
    const int cols[] = {cxx, cyy, czz};
    for (int a = 0; a < 3; ++a) {
      PlotSeries s{std::string("sigma_") + "xyz" [a], {}, {}, colors[(a + 3) % 6], false};
      for (size_t r = 0; r < n; ++r) {
        const auto v = t.Value(r, cols[a]);
        s.x.push_back(time[r]);
        s.y.push_back(v && *v >= 0 ? std::sqrt(*v) * 1e3 : NAN);
      }
      p.series.push_back(s);
    }
    emit(p, "predicted sigma per frame");
  }
  if (const int c = t.Column("rms_px"); c >= 0) {
    Plot p{"Reprojection RMS per frame", "time (s)", "RMS (px)", {}};
    PlotSeries s{"rms_px", {}, {}, colors[5], true};
    for (size_t r = 0; r < n; ++r) s.x.push_back(time[r]), s.y.push_back(t.Value(r, c).value_or(NAN));
    p.series.push_back(s);
    emit(p, "reprojection RMS per frame");
  }
  // Errors against a truth file, one axis per plot, each with its predicted 3-sigma band.
  {
    const std::string axes = "xyz";
    const int cov[] = {cxx, cyy, czz};
    for (int a = 0; a < 3; ++a) {
      const std::string h = std::string("err_") + axes[a] + "_mm";
      const int c = t.Column(h);
      if (c < 0) continue;
      Plot p{std::string("Error in ") + axes[a] + " against the truth per frame" +
                 (cov[a] >= 0 ? " (band: predicted +-3 sigma)" : ""),
             "time (s)",
             std::string(1, axes[a]) + " error (mm)",
             {}};
      PlotSeries s{"measured error", {}, {}, colors[(a + 3) % 6], true};
      for (size_t r = 0; r < n; ++r) {
        s.x.push_back(time[r]);
        s.y.push_back(t.Value(r, c).value_or(NAN));
        if (cov[a] >= 0) {
          const auto v = t.Value(r, cov[a]);
          const double b = v && *v >= 0 ? 3e3 * std::sqrt(*v) : NAN;
          s.y_low.push_back(-b);
          s.y_high.push_back(b);
        }
      }
      if (cov[a] >= 0) s.label += " (band: predicted +-3 sigma)";
      p.series.push_back(s);
      emit(p, h + " per frame");
    }
    for (size_t c = 0; c < t.header.size(); ++c) {
      const std::string& h = t.header[c];
      const bool axis_error = h == "err_x_mm" || h == "err_y_mm" || h == "err_z_mm";  // plotted above
      if (!StartsWith(h, "err") || axis_error) continue;
      Plot q{"Per-frame " + h, "time (s)", h, {}};
      PlotSeries s{h, {}, {}, colors[2], true};
      for (size_t r = 0; r < n; ++r)
        s.x.push_back(time[r]), s.y.push_back(t.Value(r, static_cast<int>(c)).value_or(NAN));
      q.series.push_back(s);
      emit(q, h + " per frame");
    }
  }
  for (size_t c = 0; c < t.header.size(); ++c) {
    const std::string h = Lower(t.header[c]);
    if (!StartsWith(h, "nees")) continue;
    const int k = h.find("pos") != std::string::npos || h.find("_p") != std::string::npos ? 3 : 6;
    const auto [lo, hi] = ChiSquareBand95(k);
    Plot p{"NEES per frame against the truth (band: 95 % of chi-square, " + std::to_string(k) + " dof)",
           "time (s)",
           t.header[c],
           {}};
    PlotSeries s{t.header[c], {}, {}, colors[3], true};
    for (size_t r = 0; r < n; ++r) {
      s.x.push_back(time[r]);
      s.y.push_back(t.Value(r, static_cast<int>(c)).value_or(NAN));
      s.y_low.push_back(lo);
      s.y_high.push_back(hi);
    }
    p.series.push_back(s);
    p.log_y = true;
    emit(p, t.header[c] + " per frame");
  }
  return figures;
}

// `mcms fuse`'s output: one fused pose per row, with the method and the sensors it fused.
bool IsFusedPoses(const Table& t) {
  return t.Column("method") >= 0 && t.Column("sensors") >= 0 && t.Column("x_m") >= 0 && t.Column("flagged") >= 0;
}

bool IsIso9283Characteristics(const Table& t) {
  return t.Column("pose") >= 0 && t.Column("AP_mm") >= 0 && t.Column("RP_mm") >= 0;
}

// Plots of an ISO 9283 characteristics table (`mcms iso9283 -o`, the demo's
// iso9283_characteristics.csv): AP per pose on a log axis in mm, and RP measured (markers)
// next to RP predicted from the covariances (lines) when the table has RP_pred_mm; one
// colour per condition.
size_t Iso9283Plots(const Table& t, const std::string& name, std::ostringstream& out) {
  const char* colors[] = {"#d62728", "#ff7f0e", "#1f77b4", "#2ca02c", "#9467bd", "#8c564b"};
  const int cp = t.Column("pose"), cc = t.Column("condition"), ca = t.Column("AP_mm"), cr = t.Column("RP_mm"),
            cq = t.Column("RP_pred_mm");
  std::vector<std::string> conditions;
  std::map<std::string, size_t> index;
  for (const auto& row : t.rows) {
    const std::string c = cc >= 0 ? row[cc] : std::string("measured");
    if (!index.count(c)) index[c] = conditions.size(), conditions.push_back(c);
  }
  Plot ap{"ISO 9283 pose accuracy AP per pose", "pose (P1..P5)", "AP (mm)", {}};
  ap.log_y = true;
  Plot rp{std::string("ISO 9283 pose repeatability RP per pose") +
              (cq >= 0 ? " (markers: measured, lines: predicted)" : ""),
          "pose (P1..P5)",
          "RP (mm)",
          {}};
  for (size_t k = 0; k < conditions.size(); ++k) {
    PlotSeries a{conditions[k], {}, {}, colors[k % 6], true},
        r = a, q{conditions[k] + " (predicted)", {}, {}, colors[k % 6], false};
    for (size_t i = 0; i < t.rows.size(); ++i) {
      if ((cc >= 0 ? t.rows[i][cc] : std::string("measured")) != conditions[k]) continue;
      // Pose "P3" -> 3; a plain number is used as it is.
      const std::string& pose = t.rows[i][cp];
      const double x =
          std::strtod(pose.c_str() + (pose.size() > 1 && (pose[0] == 'P' || pose[0] == 'p') ? 1 : 0), nullptr);
      a.x.push_back(x), a.y.push_back(t.Value(i, ca).value_or(NAN));
      r.x.push_back(x), r.y.push_back(t.Value(i, cr).value_or(NAN));
      if (cq >= 0) q.x.push_back(x), q.y.push_back(t.Value(i, cq).value_or(NAN));
    }
    ap.series.push_back(a);
    rp.series.push_back(r);
    if (cq >= 0) rp.series.push_back(q);
  }
  out << FigureHtml(ap.ToSvg(900, 420), name + ": AP per pose");
  out << FigureHtml(rp.ToSvg(900, 420), name + ": RP per pose, measured and predicted");
  return 2;
}

// The demo's answer, for the page's first screen: the flange error of each sensor and each
// fused result by the paper's three-sigma rule with the reduction, from summary.txt's table
// (rows "method points posRMS pos3sig reduction tiltRMS yawRMS NEES [band]") and its lines
// against the paper. Empty when the summary does not hold them.
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

std::string DetectKind(const std::vector<File>& files, const std::map<std::string, Table>& tables,
                       const std::map<std::string, std::string>& texts) {
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
  c.kind = DetectKind(files, tables, texts);

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
