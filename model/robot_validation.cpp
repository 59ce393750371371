#include "model/robot_validation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/statistics.h"
#include "model/tilt_sensor.h"

namespace mcms {

namespace {

PointScore Stats(int point, const std::vector<Vec3>& e) {
  PointScore s;
  s.point = point;
  s.rows = static_cast<int>(e.size());
  if (e.empty()) return s;
  std::vector<double> d, xy, z;
  double sum = 0, sq = 0;
  for (const Vec3& v : e) {
    d.push_back(v.norm());
    xy.push_back(v.head<2>().norm());
    z.push_back(std::abs(v.z()));
    sum += d.back();
    sq += d.back() * d.back();
  }
  s.mean_m = sum / s.rows;
  s.rms_m = std::sqrt(sq / s.rows);
  s.max_m = *std::max_element(d.begin(), d.end());
  s.p95_m = Percentile(d, 95.0);
  s.median_m = Percentile(d, 50.0);
  s.p95_xy_m = Percentile(xy, 95.0);
  s.p95_z_m = Percentile(z, 95.0);
  return s;
}

std::vector<PointScore> Score(const std::vector<std::vector<Vec3>>& errors, const std::vector<int>& rows) {
  std::vector<PointScore> out;
  size_t K = 0;
  for (int i : rows) K = std::max(K, errors[i].size());
  for (size_t k = 0; k < K; ++k) {
    std::vector<Vec3> e;
    for (int i : rows)
      if (k < errors[i].size()) e.push_back(errors[i][k]);
    out.push_back(Stats(static_cast<int>(k) + 1, e));
  }
  return out;
}

nlohmann::json PointJson(const PointScore& s) {
  return {{"point", s.point},       {"rows", s.rows},           {"mean_mm", s.mean_m * 1e3},
          {"median_mm", s.median_m * 1e3}, {"rms_mm", s.rms_m * 1e3}, {"p95_mm", s.p95_m * 1e3},
          {"max_mm", s.max_m * 1e3},  {"p95_xy_mm", s.p95_xy_m * 1e3}, {"p95_z_mm", s.p95_z_m * 1e3}};
}

nlohmann::json PointsJson(const std::vector<PointScore>& p) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& s : p) a.push_back(PointJson(s));
  return a;
}

const ModelScore* ModelNamed(const SessionScore& s, const std::string& name) {
  for (const ModelScore& m : s.models)
    if (m.model == name) return &m;
  return nullptr;
}

// Point 1 without -> with a cause, mean / 95 % (mm), overall and per posture group; with
// stations (a gravity-aligned instrument placed per station), the 95 % horizontal too.
std::string MovedLine(const std::string& cause, const ModelScore& without, const ModelScore& with) {
  std::string out = "    " + cause + ":";
  char b[200];
  const bool xy = !with.stations.empty();
  const auto Add = [&](const char* group, const std::vector<PointScore>& a, const std::vector<PointScore>& c) {
    if (a.empty() || c.empty()) return;
    if (xy)
      std::snprintf(b, sizeof b, " %s %.3f/%.3f/%.3f -> %.3f/%.3f/%.3f;", group, a[0].mean_m * 1e3, a[0].p95_m * 1e3,
                    a[0].p95_xy_m * 1e3, c[0].mean_m * 1e3, c[0].p95_m * 1e3, c[0].p95_xy_m * 1e3);
    else
      std::snprintf(b, sizeof b, " %s %.3f/%.3f -> %.3f/%.3f;", group, a[0].mean_m * 1e3, a[0].p95_m * 1e3,
                    c[0].mean_m * 1e3, c[0].p95_m * 1e3);
    out += b;
  };
  Add("all", without.points, with.points);
  for (const auto& [g, p] : without.groups)
    for (const auto& [g2, p2] : with.groups)
      if (g == g2) Add(Name(g), p, p2);
  out.back() = '\n';
  return out;
}

// What each cause moved on the session: the geometry (registration -> geometry) and each
// model "final without X" -> "final".
std::string MovedText(const SessionScore& s) {
  std::string lines;
  const ModelScore* reg = ModelNamed(s, "registration");
  const ModelScore* geo = ModelNamed(s, "geometry");
  const ModelScore* fin = ModelNamed(s, "final");
  const ModelScore* nom = ModelNamed(s, "nominal");
  const ModelScore* tilt = ModelNamed(s, "nominal + tilt");
  const ModelScore* geo_untilted = ModelNamed(s, "geometry without tilt");
  if (nom && tilt) lines += MovedLine("the measured tilt, nothing fitted (nominal -> nominal + tilt)", *nom, *tilt);
  if (geo_untilted && geo)
    lines += MovedLine("the measured tilt with the geometry (geometry without tilt -> geometry)", *geo_untilted, *geo);
  if (tilt && reg)
    lines += MovedLine("the tool and each station's placement (nominal + tilt -> registration)", *tilt, *reg);
  else if (nom && reg)
    lines += MovedLine("the tool and each station's placement (nominal -> registration)", *nom, *reg);
  if (reg && geo) lines += MovedLine("geometry (registration -> geometry)", *reg, *geo);
  const std::string prefix = "final without ";
  if (fin)
    for (const ModelScore& m : s.models)
      if (m.model.rfind(prefix, 0) == 0) lines += MovedLine(m.model.substr(prefix.size()), m, *fin);
  if (lines.empty()) return lines;
  const bool xy = fin && !fin->stations.empty();
  return std::string("  what each cause moved there (point 1, mean/95 %") + (xy ? "/95 % horizontal" : "") +
         " mm, without -> with it):\n" + lines;
}

}  // namespace

std::vector<Pose> MeasuredTiltCorrections(const RobotModel& robot, const RobotLog& log) {
  // A robot described without its links (a DH table) has nowhere to put a sensor.
  if (!robot.Urdf() || !log.has_stations || log.rows.empty() || log.rows.front().accel.empty()) return {};
  std::vector<LinkMount> mounts;
  for (const auto& [link, a] : log.rows.front().accel) mounts.push_back(MountOnChain(robot, link));
  const size_t ns = mounts.size();
  for (const RobotMeasurement& r : log.rows) {
    if (r.accel.size() != ns) return {};
    for (size_t k = 0; k < ns; ++k)
      if (r.accel[k].first != mounts[k].link) return {};
  }
  // Per station, each sensor's mean reading over its stationing rows.
  std::map<std::string, std::vector<Vec3>> ref;
  std::map<std::string, int> count;
  for (const RobotMeasurement& r : log.rows) {
    if (r.role != RowRole::kStationing) continue;
    auto& v = ref[r.station];
    v.resize(ns, Vec3::Zero());
    for (size_t k = 0; k < ns; ++k) v[k] += r.accel[k].second;
    ++count[r.station];
  }
  std::vector<Pose> out(log.rows.size(), Pose::Identity());
  for (size_t i = 0; i < log.rows.size(); ++i) {
    const RobotMeasurement& r = log.rows[i];
    const auto it = ref.find(r.station);
    if (it == ref.end()) continue;
    std::vector<MeasuredTilt> tilts;
    for (size_t k = 0; k < ns; ++k)
      tilts.push_back({mounts[k], TiltSince(it->second[k] / count[r.station], r.accel[k].second)});
    out[i] = TiltCorrection(robot.LinkFrames(r.q), tilts);
  }
  return out;
}

bool PlacementOptions::IsValid(std::string* why) const {
  std::string w;
  if (!noise.allFinite() || noise.llt().info() != Eigen::Success)
    w = "the position noise covariance must be finite and positive definite";
  else if (!(false_alarm > 0 && false_alarm < 0.5))
    w = "false_alarm must be in (0, 0.5), got " + std::to_string(false_alarm);
  if (why) *why = w;
  return w.empty();
}

ModelScore ScoreModel(const std::string& model, const RobotLog& log, const std::vector<std::vector<Vec3>>& predicted,
                      const std::vector<PostureGroup>& groups, const PlacementOptions& o) {
  if (std::string why; !o.IsValid(&why)) Throw("placement options: ", why);
  ModelScore m;
  m.model = model;
  const int N = static_cast<int>(log.rows.size());
  m.errors.assign(N, {});
  m.correction.assign(N, Pose::Identity());
  const auto Scored = [&](int i) { return !log.has_roles || log.rows[i].role == RowRole::kEvaluation; };
  const auto Places = [&](int i) { return !log.has_roles || log.rows[i].role == RowRole::kStationing; };
  const std::string src = log.source.empty() ? std::string("robot log") : log.source.string();
  const std::vector<std::string> names = log.has_stations ? log.Stations() : std::vector<std::string>{""};
  const Eigen::LLT<Mat3> noise(o.noise);
  for (const std::string& name : names) {
    std::vector<int> place, scored;
    for (int i = 0; i < N; ++i) {
      if (log.has_stations && log.rows[i].station != name) continue;
      if (Places(i)) place.push_back(i);
      if (Scored(i)) scored.push_back(i);
    }
    if (scored.empty()) continue;  // only spare rows: nothing to place or score
    StationPlacement pl;
    pl.station = name;
    pl.stationing_rows = static_cast<int>(place.size());
    pl.scored_rows = static_cast<int>(scored.size());
    int P = 0;
    for (int i : place) P += static_cast<int>(predicted[i].size());
    Eigen::Matrix3Xd from(3, P), to(3, P);
    P = 0;
    for (int i : place)
      for (size_t k = 0; k < predicted[i].size(); ++k, ++P) from.col(P) = predicted[i][k], to.col(P) = log.rows[i].Point(k);
    const std::string which = name.empty() ? std::string("the log") : "station '" + name + "'";
    const auto CheckPlaceable = [&](double spread) {
      if (P < 3)
        Throw(src, ": ", which, " has ", P, P == 1 ? " stationing point" : " stationing points",
              "; placing it in the instrument's frame needs at least 3 not on one line");
      if (!(spread >= 1e-3))
        Throw(src, ": the ", P, " stationing points of ", which,
              " lie on one line (or at one place); placing it in the instrument's frame needs points spread in "
              "two directions");
    };
    Pose C;  // maps the frozen placement's predictions onto the measurements
    double spread = 0.0;
    if (log.has_stations || o.fit_per_station) {
      C = RigidFit(from, to, &spread);
      CheckPlaceable(spread);
      pl.placed_anew = true;
    } else if (P >= 3) {
      // The frozen placement is kept unless it misses far beyond the noise.
      const Pose A = RigidFit(from, to, &spread);
      if (spread >= 1e-3) {
        double chi_frozen = 0, chi_placed = 0, sq_frozen = 0, sq_placed = 0;
        for (int c = 0; c < P; ++c) {
          const Vec3 e0 = from.col(c) - to.col(c), e1 = A * Vec3(from.col(c)) - Vec3(to.col(c));
          chi_frozen += noise.matrixL().solve(e0).squaredNorm();
          chi_placed += noise.matrixL().solve(e1).squaredNorm();
          sq_frozen += e0.squaredNorm();
          sq_placed += e1.squaredNorm();
        }
        pl.frozen_rms_mm = std::sqrt(sq_frozen / P) * 1e3;
        if (chi_frozen - chi_placed > ChiSquareThreshold(6, o.false_alarm) && sq_placed < 0.25 * sq_frozen) {
          C = A;
          pl.placed_anew = true;
        }
      }
    }
    if (pl.placed_anew) {
      const Vec3 c = from.rowwise().mean();
      pl.moved_mm = (C * c - c).norm() * 1e3;
      pl.moved_mrad = LogSO3(C.R).norm() * 1e3;
    }
    for (int i = 0; i < N; ++i)
      if (!log.has_stations || log.rows[i].station == name) m.correction[i] = C;
    for (int i : scored)
      for (size_t k = 0; k < predicted[i].size(); ++k) m.errors[i].push_back(C * predicted[i][k] - log.rows[i].Point(k));
    m.placements.push_back(pl);
    if (log.has_stations) {
      const std::vector<PointScore> st = Score(m.errors, scored);
      if (!st.empty()) m.stations.push_back({name, st.front()});
    }
  }
  std::vector<int> all;
  for (int i = 0; i < N; ++i)
    if (!m.errors[i].empty()) all.push_back(i);
  m.points = Score(m.errors, all);
  for (PostureGroup g : {PostureGroup::kRepeated, PostureGroup::kNewInRange, PostureGroup::kOutOfRange}) {
    std::vector<int> rows;
    for (int i : all)
      if (i < static_cast<int>(groups.size()) && groups[i] == g) rows.push_back(i);
    if (!rows.empty()) m.groups.push_back({g, Score(m.errors, rows)});
  }
  return m;
}

std::string ValidationText(const std::vector<SessionScore>& sessions) {
  std::string out;
  char b[400];
  for (const SessionScore& s : sessions) {
    int counts[3] = {0, 0, 0};
    for (size_t i = 0; i < s.group_of_row.size(); ++i)
      if (!s.models.empty() && i < s.models.front().errors.size() && !s.models.front().errors[i].empty())
        ++counts[static_cast<int>(s.group_of_row[i])];
    // Where the instrument stood, from the final model's placements (or the first model's).
    const ModelScore* pm = ModelNamed(s, "final");
    if (!pm && !s.models.empty()) pm = &s.models.front();
    std::string where = "the fit's placement, frozen";
    if (pm && !pm->placements.empty()) {
      const StationPlacement& p0 = pm->placements.front();
      if (pm->placements.size() > 1 || !p0.station.empty()) {
        std::snprintf(b, sizeof b, "each of %zu stations placed anew from its stationing rows", pm->placements.size());
        where = b;
      } else if (p0.placed_anew) {
        std::snprintf(b, sizeof b,
                      "placed anew: the fit's placement missed by %.3f mm RMS, far beyond the noise (the instrument "
                      "moved %.3f mm, %.3f mrad)",
                      p0.frozen_rms_mm, p0.moved_mm, p0.moved_mrad);
        where = b;
      }
    }
    std::snprintf(b, sizeof b,
                  "validation on %s (%d rows, %d scored: %d repeated, %d new inside the fitted ranges, %d out of "
                  "range), the robot frozen; %s:\n",
                  s.log.c_str(), s.rows, s.scored_rows, counts[0], counts[1], counts[2], where.c_str());
    out += b;
    out += "  point 1 (mm)          mean   median      RMS      95 %      max   95 % xy  95 % |z|\n";
    for (const ModelScore& m : s.models) {
      if (m.points.empty()) continue;
      const PointScore& p = m.points[0];
      std::snprintf(b, sizeof b, "  %-18s %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f", m.model.substr(0, 18).c_str(),
                    p.mean_m * 1e3, p.median_m * 1e3, p.rms_m * 1e3, p.p95_m * 1e3, p.max_m * 1e3, p.p95_xy_m * 1e3,
                    p.p95_z_m * 1e3);
      out += b;
      if (m.points.size() > 1) {
        out += "; points";
        for (const auto& q : m.points) {
          std::snprintf(b, sizeof b, " %d: %.3f", q.point, q.mean_m * 1e3);
          out += b;
        }
        out += " mm mean";
      }
      out += "\n";
    }
    for (const ModelScore& m : s.models)
      if (m.groups.size() > 1 && m.model == "final") {
        out += "  final model per posture group (point 1 mean mm):";
        for (const auto& [g, p] : m.groups)
          if (!p.empty()) {
            std::snprintf(b, sizeof b, " %s %.3f (%d);", Name(g), p[0].mean_m * 1e3, p[0].rows);
            out += b;
          }
        out.back() = '\n';
      }
    out += MovedText(s);
    if (pm && pm->stations.size() > 1) {
      // From the robot file as given where it was scored (the baseline a user of the robot
      // has), else from the registration alone.
      const ModelScore* reg = ModelNamed(s, "nominal");
      if (!reg) reg = ModelNamed(s, "registration");
      out += "  per station (point 1, mm; " + (reg ? reg->model + " -> " : std::string()) + "final): mean, 95 % xy, 95 % |z|, max\n";
      for (size_t k = 0; k < pm->stations.size(); ++k) {
        const auto& [name, p] = pm->stations[k];
        const PointScore* r = nullptr;
        if (reg)
          for (const auto& [n2, p2] : reg->stations)
            if (n2 == name) r = &p2;
        if (r)
          std::snprintf(b, sizeof b, "    %-16s %3d rows  %7.3f -> %7.3f  %7.3f -> %7.3f  %7.3f -> %7.3f  %7.3f -> %7.3f\n",
                        name.c_str(), p.rows, r->mean_m * 1e3, p.mean_m * 1e3, r->p95_xy_m * 1e3, p.p95_xy_m * 1e3,
                        r->p95_z_m * 1e3, p.p95_z_m * 1e3, r->max_m * 1e3, p.max_m * 1e3);
        else
          std::snprintf(b, sizeof b, "    %-16s %3d rows  %7.3f  %7.3f  %7.3f  %7.3f\n", name.c_str(), p.rows,
                        p.mean_m * 1e3, p.p95_xy_m * 1e3, p.p95_z_m * 1e3, p.max_m * 1e3);
        out += b;
      }
    }
  }
  return out;
}

nlohmann::json ValidationJson(const std::vector<SessionScore>& sessions) {
  nlohmann::json a = nlohmann::json::array();
  for (const SessionScore& s : sessions) {
    nlohmann::json models = nlohmann::json::array();
    for (const ModelScore& m : s.models) {
      nlohmann::json groups = nlohmann::json::object();
      for (const auto& [g, p] : m.groups)
        groups[Name(g)] = {{"rows", p.empty() ? 0 : p.front().rows}, {"points", PointsJson(p)}};
      nlohmann::json stations = nlohmann::json::array();
      for (const auto& [name, p] : m.stations) {
        nlohmann::json j = PointJson(p);
        j["station"] = name;
        stations.push_back(j);
      }
      nlohmann::json placements = nlohmann::json::array();
      for (const StationPlacement& p : m.placements)
        placements.push_back({{"station", p.station},
                              {"stationing_rows", p.stationing_rows},
                              {"scored_rows", p.scored_rows},
                              {"placed_anew", p.placed_anew},
                              {"moved_mm", p.moved_mm},
                              {"moved_mrad", p.moved_mrad}});
      models.push_back({{"model", m.model},
                        {"points", PointsJson(m.points)},
                        {"groups", groups},
                        {"stations", stations},
                        {"placements", placements}});
    }
    a.push_back({{"log", s.log}, {"rows", s.rows}, {"scored_rows", s.scored_rows}, {"models", models}});
  }
  return a;
}

}  // namespace mcms
