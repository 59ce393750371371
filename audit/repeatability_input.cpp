// The inputs of the measured-repeatability analysis (audit/repeatability.h): the measured
// points and lines as their CSV files give them, the reference, and the checks between them.
#include "audit/repeatability.h"

#include <numbers>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "core/error.h"
#include "core/nelder_mead.h"
#include "core/limits.h"
#include "core/io.h"
#include "core/statistics.h"
#include "core/svg_plot.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string Cell(const CsvTable& t, size_t row, int col) { return t.rows[row][col]; }

double NonNegative(const CsvTable& t, size_t row, int col) {
  const double v = t.Number(row, col);
  if (v < 0)
    Throw(t.source.string(), " line ", t.line_of_row[row], ", column '", t.header[col], "': expected a number >= 0, found ",
          v);
  return v;
}

// A measured standard deviation (mm) of Table 1: beyond 1 m no photogrammetry rig's
// repeatability is plausible (and the variance fit overflows near 1e154 mm).
constexpr double kMaxSigmaMm = 1000;
// The median standard deviation of a table (mm): the best photogrammetry rigs repeat a
// position to some 10 um at 1-2 m; a median below 2 um is not of a camera rig in mm (the
// paper's Table 1 in metres under _mm headers: its median, 0.3 mm, reads 0.0003).
constexpr double kMinMedianSigmaMm = 2e-3;
// A measured position (m, rig frame): a rig sees a few metres; a point beyond 10 m is
// outside any camera rig's field of view (a wrong unit or a broken row).
constexpr double kMaxPositionM = 10;

double SigmaCell(const CsvTable& t, size_t row, int col) {
  const double v = NonNegative(t, row, col);
  if (v > kMaxSigmaMm)
    Throw(t.source.string(), " line ", t.line_of_row[row], ", column '", t.header[col], "': ", v,
          " mm is not a plausible standard deviation of repeated measurements; expected 0 to ", kMaxSigmaMm, " mm");
  return v;
}

double PositionCell(const CsvTable& t, size_t row, int col) {
  const double v = t.Number(row, col);
  if (std::abs(v) > kMaxPositionM)
    Throw(t.source.string(), " line ", t.line_of_row[row], ", column '", t.header[col], "': ", v,
          " m is outside the rig's field of view; expected a position in the rig frame within +-", kMaxPositionM,
          " m (metres, not millimetres)");
  return v;
}

int IntegerCell(const CsvTable& t, size_t row, int col) {
  const double v = t.Number(row, col);
  if (v != std::floor(v) || std::abs(v) > 1e9)
    Throw(t.source.string(), " line ", t.line_of_row[row], ", column '", t.header[col], "': expected an integer, found '",
          Cell(t, row, col), "'");
  return static_cast<int>(v);
}

void CheckPlanes(const MeasuredPoints& m) {
  std::map<int, int> count;
  for (const auto& p : m.points) ++count[p.plane];
  for (const auto& [plane, n] : count)
    if (plane != 0 && n < 2)
      Throw(m.source.string(), ": plane ", plane,
            " has one point; a plane needs at least 2 points (its points are compared with each other)");
  if (m.points.size() < 3) Throw(m.source.string(), ": ", m.points.size(), " points; the fit needs at least 3");
}
}  // namespace

MeasuredPoints ReadMeasuredPoints(const fs::path& path, int table_repeats) {
  const CsvTable t = ReadCsv(path);
  MeasuredPoints m;
  m.source = path;
  if (t.rows.empty()) Throw(path.string(), ": no data rows");
  const bool table = t.HasColumn("sigma_x_mm");
  const bool raw = t.HasColumn("x_m");
  if (table == raw)
    Throw(path.string(), ": expected either Table 1 columns plane,point,sigma_x_mm,sigma_y_mm,sigma_z_mm[,sigma_d_mm] or raw "
                         "columns point,repeat,x_m,y_m,z_m[,plane]");
  std::set<std::string> seen;
  if (table) {
    if (table_repeats < 2)
      Throw(path.string(), ": a standard deviation needs at least 2 repeats, --measured-repeats is ", table_repeats);
    m.from_table = true;
    const int cp = t.Column("plane"), ci = t.Column("point"), cx = t.Column("sigma_x_mm"), cy = t.Column("sigma_y_mm"),
              cz = t.Column("sigma_z_mm");
    const int cd = t.HasColumn("sigma_d_mm") ? t.Column("sigma_d_mm") : -1;
    for (size_t r = 0; r < t.rows.size(); ++r) {
      MeasuredPoint p;
      p.plane = IntegerCell(t, r, cp);
      if (p.plane < 1)
        Throw(path.string(), " line ", t.line_of_row[r], ", column 'plane': expected a plane number >= 1, found ", p.plane);
      p.id = Cell(t, r, ci);
      if (p.id.empty()) Throw(path.string(), " line ", t.line_of_row[r], ", column 'point': empty point label");
      if (!seen.insert(p.id).second) Throw(path.string(), " line ", t.line_of_row[r], ": point ", p.id, " appears twice");
      const Vec3 s(SigmaCell(t, r, cx), SigmaCell(t, r, cy), SigmaCell(t, r, cz));
      if (!(s.minCoeff() > 0))
        Throw(path.string(), " line ", t.line_of_row[r], ": point ", p.id,
              " has a zero standard deviation; a sample of repeats never gives exactly zero");
      if (cd >= 0) {
        const double d = SigmaCell(t, r, cd);
        if (std::abs(d - s.norm()) > 0.01 * s.norm() + 0.002)
          Throw(path.string(), " line ", t.line_of_row[r], ", column 'sigma_d_mm': ", d, " is not sqrt(sx^2 + sy^2 + sz^2) = ",
                s.norm(), " of the same row");
      }
      p.repeats = table_repeats;
      p.variance = (s * 1e-3).cwiseAbs2();
      m.points.push_back(p);
    }
    // Metres under _mm headers (kMinMedianSigmaMm).
    std::vector<double> all;
    for (const MeasuredPoint& p : m.points)
      for (int k = 0; k < 3; ++k) all.push_back(std::sqrt(p.variance[k]) * 1e3);
    const double median_sigma_mm = SelectedMedian(all);  // NaN (no check) when empty
    if (median_sigma_mm < kMinMedianSigmaMm)
      Throw(path.string(), ": its standard deviations have a median of ", median_sigma_mm, " mm, below ",
            kMinMedianSigmaMm, " mm, finer than any camera rig repeats a position: values in metres under the _mm "
            "headers? expected mm");
  } else {
    // A raw CSV (point,repeat,x_m,y_m,z_m) or mcms track's poses.csv with a point column:
    // the repeat is then the frame, and lost frames (status lost, empty pose) are skipped.
    const int ci = t.Column("point"), cx = t.Column("x_m"), cy = t.Column("y_m"), cz = t.Column("z_m");
    const int cr = t.HasColumn("repeat") ? t.Column("repeat") : t.HasColumn("frame") ? t.Column("frame") : -1;
    if (cr < 0) Throw(path.string(), ": missing column 'repeat' (or 'frame', as in a poses.csv) in the header");
    const int cs = t.HasColumn("status") ? t.Column("status") : -1;
    const int cp = t.HasColumn("plane") ? t.Column("plane") : -1;
    std::map<std::string, std::vector<Vec3>> samples;
    std::map<std::string, int> plane_of;
    std::set<std::pair<std::string, std::string>> repeats;
    std::vector<std::string> order;
    for (size_t r = 0; r < t.rows.size(); ++r) {
      if (cs >= 0 && Cell(t, r, cs) == "lost") continue;
      const std::string id = Cell(t, r, ci);
      if (id.empty()) Throw(path.string(), " line ", t.line_of_row[r], ", column 'point': empty point label");
      if (!repeats.insert({id, Cell(t, r, cr)}).second)
        Throw(path.string(), " line ", t.line_of_row[r], ": point ", id, " repeat ", Cell(t, r, cr), " appears twice");
      const Vec3 x(PositionCell(t, r, cx), PositionCell(t, r, cy), PositionCell(t, r, cz));
      if (!samples.count(id)) order.push_back(id);
      samples[id].push_back(x);
      if (cp >= 0) {
        const int pl = IntegerCell(t, r, cp);
        if (plane_of.count(id) && plane_of[id] != pl)
          Throw(path.string(), " line ", t.line_of_row[r], ": point ", id, " is on plane ", plane_of[id], " and on plane ", pl);
        plane_of[id] = pl;
      }
    }
    for (const auto& id : order) {
      const auto& v = samples[id];
      if (v.size() < 2)
        Throw(path.string(), ": point ", id, " has ", v.size(),
              " repeat; a standard deviation needs at least 2 repeats of every point");
      MeasuredPoint p;
      p.id = id;
      p.plane = plane_of.count(id) ? plane_of[id] : 0;
      p.repeats = static_cast<int>(v.size());
      Vec3 mean = Vec3::Zero();
      for (const Vec3& x : v) mean += x;
      mean /= static_cast<double>(v.size());
      Vec3 var = Vec3::Zero();
      for (const Vec3& x : v) var += (x - mean).cwiseAbs2();
      var /= static_cast<double>(v.size() - 1);
      if (!(var.minCoeff() > 0))
        Throw(path.string(), ": point ", id, " has identical repeats on one axis (zero variance): not a measurement");
      p.variance = var;
      p.mean_rig = mean;
      m.points.push_back(p);
    }
    // The structure: a point's rows are repeated measurements of one position, so its
    // repeats lie close together and the points apart. Repeats spread wider than the
    // points' means are the columns mislabelled (point and repeat swapped): every "point"
    // then mixes all positions and the fit would blame a noise floor of decimetres.
    if (m.points.size() >= 2) {
      std::vector<double> within;
      Vec3 centre = Vec3::Zero();
      for (const auto& p : m.points) within.push_back(std::sqrt(p.variance.sum())), centre += *p.mean_rig;
      centre /= static_cast<double>(m.points.size());
      double between = 0;
      for (const auto& p : m.points) between += (*p.mean_rig - centre).squaredNorm();
      between = std::sqrt(between / static_cast<double>(m.points.size()));
      const double median_within = SelectedMedian(within);
      if (median_within > between)
        Throw(path.string(), ": columns '", t.header[ci], "' and '", t.header[cr],
              "' do not hold what their headers say (swapped?): the repeats of a point spread ", 1e3 * median_within,
              " mm (median) while the ", m.points.size(), " points' means lie within ", 1e3 * between,
              " mm of each other; expected each point's rows to be repeated measurements of one position "
              "(point,repeat,x_m,y_m,z_m)");
    }
  }
  CheckPlanes(m);
  return m;
}

void ApplyReference(MeasuredPoints* m, const fs::path& path) {
  if (m->from_table)
    Throw(path.string(), ": a reference needs raw repeated measurements (point,repeat,x_m,y_m,z_m), ", m->source.string(),
          " holds only standard deviations");
  const CsvTable t = ReadCsv(path);
  const int ci = t.Column("point"), cx = t.Column("x_m"), cy = t.Column("y_m"), cz = t.Column("z_m");
  std::map<std::string, Vec3> ref;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    const std::string id = Cell(t, r, ci);
    if (ref.count(id)) Throw(path.string(), " line ", t.line_of_row[r], ": point ", id, " appears twice");
    ref[id] = Vec3(t.Number(r, cx), t.Number(r, cy), t.Number(r, cz));
  }
  std::set<std::string> measured;
  for (auto& p : m->points) {
    measured.insert(p.id);
    const auto it = ref.find(p.id);
    if (it == ref.end())
      Throw(path.string(), ": no reference for point ", p.id, " measured in ", m->source.string(),
            "; the reference must hold the same points");
    p.reference = it->second;
  }
  for (const auto& [id, x] : ref)
    if (!measured.count(id))
      Throw(path.string(), ": point ", id, " is not among the measured points of ", m->source.string(),
            "; the reference must hold the same points");
}

MeasuredLines ReadMeasuredLines(const fs::path& path) {
  const CsvTable t = ReadCsv(path);
  if (t.rows.empty()) Throw(path.string(), ": no data rows");
  MeasuredLines out;
  out.source = path;
  const int cp = t.Column("plane"), cl = t.Column("line"), cr = t.Column("d_laser_mm"), cm = t.Column("d_camera_mm");
  const int cd = t.HasColumn("delta_mm") ? t.Column("delta_mm") : -1;
  const int cf = t.HasColumn("from") ? t.Column("from") : -1, ct = t.HasColumn("to") ? t.Column("to") : -1;
  if ((cf >= 0) != (ct >= 0)) Throw(path.string(), ": columns 'from' and 'to' come together");
  std::set<std::pair<int, std::string>> seen;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    MeasuredLine l;
    l.plane = IntegerCell(t, r, cp);
    l.id = Cell(t, r, cl);
    if (!seen.insert({l.plane, l.id}).second)
      Throw(path.string(), " line ", t.line_of_row[r], ": line ", l.id, " of plane ", l.plane, " appears twice");
    const double dl = t.Number(r, cr), dc = t.Number(r, cm);
    if (!(dl > 0 && dc > 0)) Throw(path.string(), " line ", t.line_of_row[r], ": line lengths must be positive");
    if (cd >= 0) {
      const double delta = t.Number(r, cd);
      if (std::abs(delta - (dl - dc)) > 0.0015)
        Throw(path.string(), " line ", t.line_of_row[r], ", column 'delta_mm': ", delta, " is not d_laser_mm - d_camera_mm = ",
              dl - dc);
    }
    l.d_reference_m = dl * 1e-3;
    l.d_measured_m = dc * 1e-3;
    if (cf >= 0) l.from = Cell(t, r, cf), l.to = Cell(t, r, ct);
    out.lines.push_back(l);
  }
  return out;
}

void CheckLinesAgainstPoints(const MeasuredLines& lines, const MeasuredPoints& points) {
  std::set<int> planes;
  std::set<std::string> ids;
  for (const auto& p : points.points) planes.insert(p.plane), ids.insert(p.id);
  const auto list = [](const auto& set, size_t max) {
    std::ostringstream o;
    size_t n = 0;
    for (const auto& x : set) {
      if (n++ == max) {
        o << ", ...";
        break;
      }
      o << (n > 1 ? ", " : "") << x;
    }
    return o.str();
  };
  const bool planed = !planes.count(0);
  for (const auto& l : lines.lines) {
    if (!l.from.empty()) {
      for (const std::string& end : {l.from, l.to})
        if (!ids.count(end))
          Throw(lines.source.string(), ": line ", l.id, " of plane ", l.plane, " joins ", l.from, " and ", l.to,
                "; point ", end, " is not among the measured points of ", points.source.string(), " (they are ",
                list(ids, 20), "); expected lines between measured points");
    }
    if (planed && !planes.count(l.plane))
      Throw(lines.source.string(), ": line ", l.id, " is on plane ", l.plane, ", which the measurements ",
            points.source.string(), " lack (they have plane", planes.size() > 1 ? "s " : " ", list(planes, 20),
            "); expected lines of the measured planes");
  }
}

}  // namespace mcms
