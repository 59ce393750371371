#include "model/robot_measurements.h"
#include "model/robot_measurements_internal.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <numeric>
#include <set>
#include <sstream>

#include <Eigen/Dense>
#include <yaml-cpp/yaml.h>

#include "core/format.h"
#include "core/limits.h"
#include "core/error.h"
#include "core/io.h"
#include "core/statistics.h"
#include "core/yaml.h"
#include "model/tilt_sensor.h"
#include "model/urdf.h"

namespace mcms {

std::string robot_log_internal::JointName(const RobotModel& robot, int i) {
  const std::string& n = robot.Joints()[i].name;
  return n.empty() ? "joint " + std::to_string(i + 1) : n;
}

using robot_log_internal::JointName;

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}


// ---- YAML ------------------------------------------------------------------------

Pose ParsePoseNode(const YAML::Node& n, const std::string& where) {
  for (const char* k : {"x", "y", "z", "qw", "qx", "qy", "qz"})
    if (!n[k]) Throw(where, ": pose is missing '", k, "'");
  const Eigen::Quaterniond q(n["qw"].as<double>(), n["qx"].as<double>(), n["qy"].as<double>(), n["qz"].as<double>());
  if (!IsUnitQuaternion(q)) Throw(where, ": pose quaternion has norm ", q.norm(), ", expected 1");
  return Pose::FromQuaternion(q.normalized(), Vec3(n["x"].as<double>(), n["y"].as<double>(), n["z"].as<double>()));
}

std::vector<double> ReadList(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence()) Throw(where, " must be a list of numbers");
  std::vector<double> v;
  for (const auto& e : n) {
    const double d = e.as<double>();
    if (!std::isfinite(d)) Throw(where, " has a non-finite number");
    v.push_back(d);
  }
  return v;
}

// ---- CSV -------------------------------------------------------------------------

}  // namespace

JointColumns FindJointColumns(const CsvTable& t, const RobotModel& robot, std::set<int>* used) {
  const std::string src = t.source.string();
  // The joints a log records: the actuated ones (a mimic joint's driver, not the mimic).
  const auto& act = robot.ActuatedJoints();
  const int n = robot.NumActuated();
  const auto JointName = [&](const RobotModel&, int i) {
    return act[i].name.empty() ? "joint " + std::to_string(i + 1) : act[i].name;
  };
  JointColumns jc{std::vector<int>(n, -1), std::vector<double>(n, 1.0)};
  const auto Find = [&](const std::string& name) {
    for (size_t c = 0; c < t.header.size(); ++c)
      if (t.header[c] == name) return static_cast<int>(c);
    return -1;
  };
  // Numbered columns q1_rad.. (q<i>_deg, q<i>_m): the highest number the log has (a
  // missing one below it is named below, not counted).
  int numbered = 0;
  for (int i = 1; i <= kMaxRobotJoints + 1; ++i) {
    const std::string q = std::string("q").append(std::to_string(i));  // (GCC 12 -Wrestrict misfires on "q" + ...)
    if (Find(q + "_rad") >= 0 || Find(q + "_deg") >= 0 || Find(q + "_m") >= 0) numbered = i;
  }
  // A robot whose URDF names its joints q<k> itself (q6 .. q1 down the chain, say): its
  // q<k> columns are its joint names, read by name, never by their number.
  bool numbers_are_names = numbered > 0;
  for (int i = 1; numbers_are_names && i <= numbered; ++i) {
    const std::string q = std::string("q").append(std::to_string(i));
    numbers_are_names = std::any_of(act.begin(), act.end(), [&](const auto& j) { return j.name == q; });
  }
  if (numbers_are_names) numbered = 0;
  const auto Take = [&](int i, const std::string& stem, const std::string& label) {
    const bool rev = act[i].type == JointType::kRevolute;
    std::vector<std::pair<std::string, double>> units;
    if (rev)
      units = {{stem + "_rad", 1.0}, {stem + "_deg", kDeg}};
    else
      units = {{stem + "_m", 1.0}};
    if (!label.empty()) units.push_back({stem, 1.0});
    std::string found_name;
    for (const auto& [name, s] : units) {
      const int c = Find(name);
      if (c < 0) continue;
      if (jc.column[i] >= 0)
        Throw(src, ": joint ", JointName(robot, i), " has two columns, '", found_name, "' and '", name,
              "'; give one");
      jc.column[i] = c;
      jc.scale[i] = s;
      found_name = name;
    }
    const std::string wrong = rev ? stem + "_m" : stem + "_rad";
    if (jc.column[i] < 0 && (Find(wrong) >= 0 || (!rev && Find(stem + "_deg") >= 0)))
      Throw(src, ": column '", Find(wrong) >= 0 ? wrong : stem + "_deg", "' is for a ",
            rev ? "prismatic" : "revolute", " joint, but joint ", JointName(robot, i), " of robot '", robot.Name(),
            "' is ", rev ? "revolute (give " + stem + "_rad or " + stem + "_deg)" : "prismatic (give " + stem + "_m)");
    if (jc.column[i] >= 0) used->insert(jc.column[i]);
  };
  if (numbered > 0) {
    // A joint given twice, numbered and by its name: which one is meant is not for the
    // reader to guess.
    for (int i = 0; i < n; ++i)
      for (const std::string& suffix : {std::string(), std::string("_rad"), std::string("_deg"), std::string("_m")})
        if (!act[i].name.empty() && Find(act[i].name + suffix) >= 0)
          Throw(src, ": joint ", act[i].name, " has two columns, 'q", i + 1, "...' and '", act[i].name + suffix,
                "'; give one");
    const std::string joints =
        robot.HasMimicJoints() ? " actuated joints (its mimic joints follow them)" : " joints";
    if (numbered > n)
      Throw(src, ": ", numbered, " joint columns (q1 .. q", numbered, ") but robot '", robot.Name(), "' has ", n,
            joints, "; give the robot description the log was measured with (--robot)");
    for (int i = 0; i < n; ++i) {
      Take(i, std::string("q").append(std::to_string(i + 1)), "");
      if (jc.column[i] < 0)
        Throw(src, ": no column for joint ", i + 1, act[i].name.empty() ? "" : " ('" + act[i].name + "')", " (q", i + 1,
              act[i].type == JointType::kRevolute ? "_rad or q" + std::to_string(i + 1) + "_deg" : "_m", "); robot '",
              robot.Name(), "' has ", n, joints, numbered < n ? ": give the robot description the log was measured "
                                                                "with (--robot), or the missing column" : "");
    }
    return jc;
  }
  // Columns named as the robot names its joints.
  std::vector<std::string> missing;
  for (int i = 0; i < n; ++i) {
    const std::string& name = act[i].name;
    if (!name.empty()) Take(i, name, name);
    if (jc.column[i] < 0) missing.push_back(name.empty() ? "joint " + std::to_string(i + 1) : name);
  }
  if (missing.size() == static_cast<size_t>(n)) {
    std::string names;
    for (int i = 0; i < n; ++i) names += (i ? ", " : "") + JointName(robot, i);
    Throw(src, ": no joint columns; expected q1_rad..q", n, "_rad or the robot's joint names (", names, ")");
  }
  if (!missing.empty()) {
    std::string m;
    for (size_t k = 0; k < missing.size(); ++k) m += (k ? ", " : "") + missing[k];
    Throw(src, ": the chain's joint", missing.size() > 1 ? "s " : " ", m, missing.size() > 1 ? " are" : " is",
          " not in the log (robot '", robot.Name(), "'); give one column per joint of the chain");
  }
  // A column naming a joint of the robot's URDF that is not in the chain.
  if (const UrdfSource* u = robot.Urdf())
    for (const std::string& j : u->all_joints)
      for (const std::string& suffix : {std::string(), std::string("_rad"), std::string("_deg"), std::string("_m")}) {
        const int c = Find(j + suffix);
        if (c >= 0 && !used->count(c))
          Throw(src, ": column '", t.header[c], "' is joint ", j, " of the URDF, which is not in the chain from '",
                u->base_link, "' to '", u->tip_link, "'; give --base-link/--tip-link for the chain the log moves, "
                "or remove the column");
      }
  return jc;
}

namespace {

RobotLog ReadCsvLog(const std::filesystem::path& path, const RobotModel& robot) {
  const CsvTable t = ReadCsv(path);
  const std::string src = path.string();
  RobotLog log;
  log.source = path;
  std::set<int> used;
  const JointColumns jc = FindJointColumns(t, robot, &used);
  const auto Find = [&](const std::string& name) {
    for (size_t c = 0; c < t.header.size(); ++c)
      if (t.header[c] == name) return static_cast<int>(c);
    return -1;
  };
  const auto Use = [&](const std::string& name) {
    const int c = Find(name);
    if (c >= 0) used.insert(c);
    return c;
  };
  // Time.
  int ct = Use("time_s"), cts = -1, cte = -1;
  if (ct < 0) {
    cts = Use("t_start_robot");
    cte = Use("t_end_robot");
    if ((cts < 0) != (cte < 0)) Throw(src, ": give both t_start_robot and t_end_robot, or time_s");
  }
  log.has_time = ct >= 0 || cts >= 0;
  // Points: x_m, y_m, z_m or x1, y1, z1 .. xK, yK, zK.
  std::vector<std::array<int, 3>> pts;
  const int cx = Use("x_m"), cy = Use("y_m"), cz = Use("z_m");
  if (cx >= 0 || cy >= 0 || cz >= 0) {
    if (cx < 0 || cy < 0 || cz < 0) Throw(src, ": give all of x_m, y_m, z_m (the measured point, metres)");
    pts.push_back({cx, cy, cz});
  }
  for (int k = 1;; ++k) {
    std::array<int, 3> c{};
    bool any = false, all = true;
    for (int a = 0; a < 3; ++a) {
      const std::string stem = std::string(1, "xyz"[a]) + std::to_string(k);
      const int bare = Use(stem), unit = Use(stem + "_m");
      if (bare >= 0 && unit >= 0)
        Throw(src, ": point ", k, " has both '", stem, "' and '", stem, "_m'; give one");
      c[a] = bare >= 0 ? bare : unit;
      any |= c[a] >= 0;
      all &= c[a] >= 0;
    }
    if (!any) break;
    if (!all) Throw(src, ": point ", k, " needs x", k, ", y", k, " and z", k, " (metres)");
    if (!pts.empty() && k == 1 && cx >= 0)
      Throw(src, ": give the measured point as x_m, y_m, z_m or as points x1, y1, z1 .., not both");
    pts.push_back(c);
  }
  if (pts.empty())
    Throw(src, ": no measured position; expected x_m, y_m, z_m (one point) or x1, y1, z1, .., xK, yK, zK (K points of "
               "one rigid body), metres");
  if (pts.size() == 2)
    Throw(src, ": 2 points per row do not fix the tool's pose and are not one point; give one point or at least 3 "
               "points of the rigid body");
  const bool has_q = Find("qw") >= 0 || Find("qx") >= 0 || Find("qy") >= 0 || Find("qz") >= 0;
  int cqw = -1, cqx = -1, cqy = -1, cqz = -1;
  if (has_q) {
    if (pts.size() > 1) Throw(src, ": a measured orientation (qw, qx, qy, qz) goes with one point, not ", pts.size());
    cqw = Use("qw"), cqx = Use("qx"), cqy = Use("qy"), cqz = Use("qz");
    if (cqw < 0 || cqx < 0 || cqy < 0 || cqz < 0) Throw(src, ": give all of qw, qx, qy, qz (unit quaternion)");
  }
  const int ctemp = Use("temperature_c"), cpay = Use("payload_kg");
  log.has_temperature = ctemp >= 0;
  log.has_payload = cpay >= 0;
  const int cstation = Use("station"), crole = Use("role");
  log.has_stations = cstation >= 0;
  log.has_roles = crole >= 0;
  // Accelerometers on the URDF's links (issue 52): <link>_ax, <link>_ay, <link>_az, m/s^2.
  std::vector<std::pair<std::string, std::array<int, 3>>> accel;
  for (size_t c = 0; c < t.header.size(); ++c) {
    const std::string& h = t.header[c];
    if (h.size() <= 3 || h.compare(h.size() - 3, 3, "_ax") != 0) continue;
    const std::string link = h.substr(0, h.size() - 3);
    const int ay = Use(link + "_ay"), az = Use(link + "_az");
    used.insert(static_cast<int>(c));
    if (ay < 0 || az < 0)
      Throw(src, ": column '", h, "' is an accelerometer's x; give ", link, "_ax, ", link, "_ay and ", link,
            "_az (m/s^2, in the sensor's frame)");
    if (!robot.Urdf())
      Throw(src, ": column '", h, "' reads an accelerometer on link '", link,
            "', but robot '", robot.Name(), "' is a DH table: give the robot as a URDF that names its links");
    MountOnChain(robot, link);  // InputError naming the link: not in the URDF, or off the chain
    accel.push_back({link, {static_cast<int>(c), ay, az}});
  }
  for (size_t c = 0; c < t.header.size(); ++c)
    if (!used.count(static_cast<int>(c))) log.ignored_columns.push_back(t.header[c]);
  const int n = robot.NumActuated();
  for (size_t i = 0; i < t.rows.size(); ++i) {
    RobotMeasurement r;
    r.line = t.line_of_row[i];
    r.source = src + " line " + std::to_string(r.line);
    if (ct >= 0)
      r.time_s = t.Number(i, ct);
    else if (cts >= 0)
      r.time_s = 0.5 * (t.Number(i, cts) + t.Number(i, cte));
    else
      r.time_s = static_cast<double>(i);
    Eigen::VectorXd qa(n);
    for (int j = 0; j < n; ++j) qa[j] = t.Number(i, jc.column[j]) * jc.scale[j];
    r.q = robot.ChainValues(qa);
    for (size_t k = 0; k < pts.size(); ++k) {
      const Vec3 p(t.Number(i, pts[k][0]), t.Number(i, pts[k][1]), t.Number(i, pts[k][2]));
      if (k == 0)
        r.p_meas = p;
      else
        r.other_points.push_back(p);
    }
    if (has_q) {
      const Eigen::Quaterniond qq(t.Number(i, cqw), t.Number(i, cqx), t.Number(i, cqy), t.Number(i, cqz));
      if (!IsUnitQuaternion(qq))
        Throw(src, " line ", r.line, ": quaternion (qw, qx, qy, qz) has norm ", qq.norm(), "; expected 1");
      r.R_meas_tool = qq.normalized().toRotationMatrix();
    }
    if (ctemp >= 0) r.temperature_c = t.Number(i, ctemp);
    if (cpay >= 0) r.payload_kg = t.Number(i, cpay);
    for (const auto& [link, c] : accel) {
      const Vec3 a(t.Number(i, c[0]), t.Number(i, c[1]), t.Number(i, c[2]));
      CheckAccelerometerReading(a, src + " line " + std::to_string(r.line) + ", columns " + link + "_ax.._az");
      r.accel.push_back({link, a});
    }
    if (cstation >= 0) {
      r.station = t.rows[i][cstation];
      if (r.station.empty())
        Throw(src, " line ", r.line, ": the station cell is empty; give every row its station (any label)");
    }
    if (crole >= 0) {
      const std::string v = Lower(t.rows[i][crole]);
      if (v.empty() || v == "evaluation")
        r.role = RowRole::kEvaluation;
      else if (v == "stationing")
        r.role = RowRole::kStationing;
      else if (v == "spare")
        r.role = RowRole::kSpare;
      else
        Throw(src, " line ", r.line, ": role '", t.rows[i][crole],
              "' is not understood; expected stationing (places its station), evaluation (scored; also an empty "
              "cell) or spare");
    }
    log.rows.push_back(r);
  }
  return log;
}

// q with every joint but j at the middle of its range (to test joint j's limits alone).
Eigen::VectorXd JointOnly(const RobotModel& robot, const Eigen::VectorXd& q, int j) {
  Eigen::VectorXd m(robot.NumJoints());
  for (int i = 0; i < robot.NumJoints(); ++i) {
    const Joint& jt = robot.Joints()[i];
    m[i] = std::isfinite(jt.lower) && std::isfinite(jt.upper) ? 0.5 * (jt.lower + jt.upper)
           : std::isfinite(jt.lower)                          ? jt.lower
           : std::isfinite(jt.upper)                          ? jt.upper
                                                              : 0.0;
  }
  m[j] = q[j];
  return m;
}

// A joint value outside the limits that would fit them in another unit.
std::string UnitHint(const RobotModel& robot, const RobotLog& log, int j) {
  const Joint& jt = robot.Joints()[j];
  const auto fits = [&](double s) {
    for (const auto& r : log.rows)
      if (!(r.q[j] * s >= jt.lower - 1e-9 && r.q[j] * s <= jt.upper + 1e-9)) return false;
    return true;
  };
  double big = 0;
  for (const auto& r : log.rows) big = std::max(big, std::abs(r.q[j]));
  if (jt.type == JointType::kRevolute) {
    if (fits(kDeg) && big > 2 * kPi)
      return " (the column looks like degrees: every value fits the limits in degrees; give radians, or name the "
             "column _deg)";
  } else {
    if (fits(1e-3) && big > 1.0)
      return " (the column looks like millimetres: every value fits the limits in mm; give metres)";
  }
  return "";
}

}  // namespace

const char* Name(RowRole r) {
  switch (r) {
    case RowRole::kStationing: return "stationing";
    case RowRole::kSpare: return "spare";
    default: return "evaluation";
  }
}

std::vector<std::string> RobotLog::Stations() const {
  std::vector<std::string> s;
  for (const auto& r : rows)
    if (std::find(s.begin(), s.end(), r.station) == s.end()) s.push_back(r.station);
  if (s.empty()) s.push_back("");
  return s;
}

std::string RobotLog::Where(size_t i) const {
  if (i < rows.size() && !rows[i].source.empty()) return rows[i].source;
  std::ostringstream o;
  o << (source.empty() ? std::string("robot log") : source.string());
  if (i < rows.size() && rows[i].line > 0)
    o << " line " << rows[i].line;
  else
    o << " row " << i + 1;
  return o.str();
}

void CheckRobotLog(const RobotLog& log, const RobotModel& robot, int min_rows) {
  const std::string src = log.source.empty() ? std::string("robot log") : log.source.string();
  if (log.rows.empty()) Throw(src, ": no measurements");
  if (static_cast<int>(log.rows.size()) < min_rows)
    Throw(src, ": ", log.rows.size(), log.rows.size() == 1 ? " measurement" : " measurements", "; at least ", min_rows,
          " are needed (the registration alone has 9 parameters; repeated poses over time show the noise)");
  const bool six = log.rows.front().R_meas_tool.has_value();
  const int K = log.rows.front().NumPoints();
  for (size_t i = 0; i < log.rows.size(); ++i) {
    const RobotMeasurement& r = log.rows[i];
    if (r.q.size() != robot.NumJoints())
      Throw(log.Where(i), ": ", r.q.size(), " joint values but robot '", robot.Name(), "' has ", robot.NumJoints(),
            " joints; give the robot description the log was measured with (--robot)");
    for (int j = 0; j < robot.NumJoints(); ++j)
      if (!std::isfinite(r.q[j])) Throw(log.Where(i), ": the value of joint ", JointName(robot, j), " is not finite");
    std::string why;
    if (!robot.WithinLimits(r.q, &why, RobotModel::kLimitSlack)) {
      std::string hint;
      for (int j = 0; j < robot.NumJoints() && hint.empty(); ++j)
        if (!robot.WithinLimits(JointOnly(robot, r.q, j), nullptr, RobotModel::kLimitSlack))
          hint = UnitHint(robot, log, j);
      Throw(log.Where(i), ": ", why, " (by more than the ", Num4(100 * RobotModel::kLimitSlack),
            " % of its range a reading may)", hint);
    }
    if (!r.p_meas.allFinite()) Throw(log.Where(i), ": the measured position is not finite");
    for (const Vec3& p : r.other_points)
      if (!p.allFinite()) Throw(log.Where(i), ": a measured point is not finite");
    if (r.NumPoints() != K) Throw(log.Where(i), ": ", r.NumPoints(), " points, but the first row has ", K);
    if (!std::isfinite(r.time_s)) Throw(log.Where(i), ": time_s is not finite");
    if (i > 0 && r.time_s < log.rows[i - 1].time_s)
      Throw(log.Where(i), ": time ", r.time_s, " s is before the previous row's ", log.rows[i - 1].time_s,
            " s; rows must be in time order");
    if (r.R_meas_tool.has_value() != six)
      Throw(log.Where(i), ": some rows have a measured orientation and some do not; give all or none");
    const double temperature = r.temperature_c.value_or(std::nan("")), payload = r.payload_kg.value_or(std::nan(""));
    if (log.has_temperature && !(temperature >= kMinTemperatureC && temperature <= kMaxTemperatureC))
      Throw(log.Where(i), ": temperature_c is ", temperature, "; expected ", kMinTemperatureC, " to ",
            kMaxTemperatureC, " deg C");
    if (log.has_payload && !(std::isfinite(payload) && payload >= 0 && payload <= kMaxMassKg))
      Throw(log.Where(i), ": payload_kg is ", payload, "; expected a finite mass from 0 to ", kMaxMassKg, " kg");
  }
  // Each accelerometer against its mount in the URDF: with the robot standing within 45 deg
  // of level (a construction site's slope is a few degrees), a sensor reads up within 45 deg
  // of the up its mount predicts. A median beyond that is a sensor mounted other than the
  // URDF says, or columns swapped or of the other sign: its tilts would be read as a bias
  // of tens of degrees.
  if (!log.rows.front().accel.empty() && robot.Urdf()) {
    const auto& first = log.rows.front().accel;
    for (size_t k = 0; k < first.size(); ++k) {
      const LinkMount mount = MountOnChain(robot, first[k].first);
      std::vector<double> angle;
      for (const RobotMeasurement& r : log.rows) {
        if (k >= r.accel.size() || r.accel[k].first != first[k].first) break;
        const Mat3 R_base_sensor = robot.LinkFrames(r.q)[mount.frame].R * mount.R_frame_link;
        const Vec3 up = R_base_sensor.transpose() * Vec3::UnitZ();
        angle.push_back(std::acos(std::clamp(up.dot(r.accel[k].second.normalized()), -1.0, 1.0)));
      }
      if (angle.empty()) continue;
      std::nth_element(angle.begin(), angle.begin() + angle.size() / 2, angle.end());
      const double median = angle[angle.size() / 2];
      if (median > kPi / 4)
        Throw(src, ": the accelerometer on ", first[k].first, " (", first[k].first, "_ax, _ay, _az) reads up ",
              Num4(median * 180 / kPi), " deg (median over the rows) from where its mount in the URDF puts up with "
              "the robot level, more than the 45 deg a standing robot tilts: mounted upside down or turned, or its "
              "columns swapped or of the other sign? expected the specific force, +9.81 m/s^2 along the sensor's up");
    }
  }
}

namespace {

// Hilti's construction-robot stationing datasets as published (see the header).
bool IsStationingDataset(const YAML::Node& root) {
  return root.IsMap() && root["joint_names"] && root["column_heights"];
}

RobotLog ReadStationingDataset(const std::filesystem::path& path, const YAML::Node& root, const RobotModel& robot) {
  const std::string src = "measurement file " + path.string();
  RobotLog log;
  log.source = path;
  log.has_time = log.has_stations = log.has_roles = true;
  // The file's joints against the robot's actuated joints, by name.
  std::vector<std::string> names;
  for (const auto& n : root["joint_names"]) names.push_back(n.as<std::string>());
  const auto& act = robot.ActuatedJoints();
  std::vector<int> column(act.size(), -1);
  for (size_t a = 0; a < act.size(); ++a)
    for (size_t k = 0; k < names.size(); ++k)
      if (names[k] == act[a].name) column[a] = static_cast<int>(k);
  for (size_t a = 0; a < act.size(); ++a)
    if (column[a] < 0) {
      std::string list;
      for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
      Throw(src, ": joint_names (", list, ") has no '", act[a].name, "', a joint of robot '", robot.Name(),
            "'; give the robot the dataset was recorded with (--robot, and --tip-link for the measured point)");
    }
  // The square of stationing points the publisher's protocol uses (arm commands, m).
  static const double kSquare[4][3] = {{0.1, 0.15, 0.48}, {0.1, -0.15, 0.48}, {0.4, 0.15, 0.48}, {0.4, -0.15, 0.48}};
  const auto InSquare = [](const std::vector<double>& c) {
    for (const auto& s : kSquare)
      if (c.size() == 3 && std::abs(c[0] - s[0]) < 1e-6 && std::abs(c[1] - s[1]) < 1e-6 && std::abs(c[2] - s[2]) < 1e-6)
        return true;
    return false;
  };
  struct Timed {
    double time;
    RobotMeasurement m;
  };
  std::vector<Timed> rows;
  int unplaced = 0, unplaced_stations = 0;
  for (const auto& hk : root["column_heights"]) {
    const std::string height = hk.first.as<std::string>();
    const YAML::Node spaces = hk.second["solution_spaces"];
    if (!spaces || !spaces.IsMap()) Throw(src, ": column height ", height, " has no 'solution_spaces' map");
    for (const auto& sk : spaces) {
      const std::string station = height + " m / " + sk.first.as<std::string>();
      const YAML::Node st = sk.second["stationing_measurements"], ev = sk.second["evaluation_measurements"];
      const bool placed = st && st.IsSequence() && st.size() > 0;
      for (const auto& [list, stationing] : {std::pair{st, true}, std::pair{ev, false}}) {
        if (!list) continue;
        if (!list.IsSequence()) Throw(src, ": station ", station, ": expected a list of measurements");
        for (const auto& e : list) {
          const std::string where = src + " station " + station + " measurement " +
                                    (e["id"] ? e["id"].as<std::string>() : std::string("?")) + " (line " +
                                    std::to_string(e.Mark().line + 1) + ")";
          for (const char* k : {"time", "joint_states", "prism_position"})
            if (!e[k]) Throw(where, ": missing '", k, "'");
          const auto q = ReadList(e["joint_states"], where + " joint_states");
          if (q.size() != names.size())
            Throw(where, ": ", q.size(), " joint_states but ", names.size(), " joint_names");
          const auto p = ReadList(e["prism_position"], where + " prism_position");
          if (p.size() != 3) Throw(where, ": prism_position must have 3 numbers, has ", p.size());
          Timed t;
          t.time = e["time"].as<double>();
          if (!std::isfinite(t.time)) Throw(where, ": time is not finite");
          Eigen::VectorXd qa(act.size());
          for (size_t a = 0; a < act.size(); ++a) qa[a] = q[column[a]];
          t.m.q = robot.ChainValues(qa);
          t.m.p_meas = Vec3(p[0], p[1], p[2]);
          t.m.station = station;
          if (stationing) {
            const auto cmd = e["doosan_cmd"] ? ReadList(e["doosan_cmd"], where + " doosan_cmd") : std::vector<double>{};
            t.m.role = InSquare(cmd) ? RowRole::kStationing : RowRole::kSpare;
          } else {
            t.m.role = placed ? RowRole::kEvaluation : RowRole::kSpare;
            if (!placed) ++unplaced;
          }
          // The two ADXL355 read as tilt sensors, named by the URDF links they sit on.
          for (const auto& [key, link] : {std::pair<const char*, const char*>{"tilt_sensor_base_accel", "tilt_sensor_base"},
                                          {"tilt_sensor_column_accel", "tilt_sensor_column_tip"}})
            if (e[key]) {
              const auto a = ReadList(e[key], where + " " + key);
              if (a.size() != 3) Throw(where, ": ", key, " must have 3 numbers, has ", a.size());
              CheckAccelerometerReading(Vec3(a[0], a[1], a[2]), where + " " + key);
              t.m.accel.push_back({link, Vec3(a[0], a[1], a[2])});
            }
          t.m.line = e.Mark().line + 1;
          t.m.source = where;
          rows.push_back(t);
        }
      }
      if (!placed && ev && ev.size() > 0) ++unplaced_stations;
    }
  }
  if (rows.empty()) Throw(src, ": no measurements under column_heights");
  std::stable_sort(rows.begin(), rows.end(), [](const Timed& a, const Timed& b) { return a.time < b.time; });
  for (const Timed& t : rows) {
    log.rows.push_back(t.m);
    log.rows.back().time_s = t.time;
  }
  if (unplaced > 0)
    log.notes.push_back(path.filename().string() + ": " + std::to_string(unplaced) + " evaluation points of " +
                        std::to_string(unplaced_stations) +
                        " stations without stationing points (nothing places them) are spare, as in the "
                        "publisher's protocol");
  return log;
}

}  // namespace

RobotLog ReadRobotLog(const std::filesystem::path& path, const RobotModel& robot) {
  const std::string ext = Lower(path.extension().string());
  RobotLog log;
  YAML::Node root;
  if (ext == ".yaml" || ext == ".yml") {
    try {
      root = LoadYaml(ReadTextFile(path), "measurement file " + path.string());
    } catch (const YAML::Exception& e) {
      Throw("measurement file ", path.string(), ": not valid YAML: ", e.what());
    }
  }
  if (IsStationingDataset(root)) {
    try {
      log = ReadStationingDataset(path, root, robot);
    } catch (const YAML::Exception& e) {
      Throw("measurement file ", path.string(), ": ", e.what());
    }
  } else if (ext == ".yaml" || ext == ".yml") {
    log.source = path;
    std::vector<RobotMeasurement> m = ReadRobotMeasurements(path);
    for (size_t i = 0; i < m.size(); ++i) {
      m[i].time_s = static_cast<double>(i);
      // The file's joints are the actuated ones: a mimic joint follows its driver.
      if (robot.HasMimicJoints() && m[i].q.size() == robot.NumActuated()) m[i].q = robot.ChainValues(m[i].q);
    }
    log.rows = std::move(m);
  } else {
    log = ReadCsvLog(path, robot);
  }
  CheckRobotLog(log, robot);
  return log;
}

RobotModel CoverReadings(const RobotModel& robot, const std::vector<const RobotLog*>& logs,
                         std::vector<std::string>* notes) {
  std::vector<Joint> joints = robot.Joints();
  bool changed = false;
  for (int j = 0; j < robot.NumJoints(); ++j) {
    Joint& jt = joints[j];
    const double lower = jt.lower, upper = jt.upper;
    std::string where;
    for (const RobotLog* log : logs)
      for (const auto& r : log->rows) {
        if (j >= r.q.size()) continue;
        if (r.q[j] < jt.lower) jt.lower = r.q[j], where = log->source.filename().string();
        if (r.q[j] > jt.upper) jt.upper = r.q[j], where = log->source.filename().string();
      }
    if (jt.lower == lower && jt.upper == upper) continue;
    changed = true;
    if (notes) {
      const bool rev = jt.type == JointType::kRevolute;
      const auto Text = [&](double v) { return rev ? Num4(v / kDeg) + " deg" : Num4(v * 1e3) + " mm"; };
      notes->push_back("joint " + JointName(robot, j) + " reads past its limit by up to " +
                       Text(std::max(lower - jt.lower, jt.upper - upper)) + " (" + where + "; within the " +
                       Num4(100 * RobotModel::kLimitSlack) + " % of its range a reading may): its limits are widened " +
                       "to the readings");
    }
  }
  return changed ? robot.WithJoints(joints) : robot;
}

RobotLog KeepPoints(const RobotLog& log, const std::vector<int>& keep, const std::string& option) {
  RobotLog out = log;
  if (keep.empty()) return out;
  const int K = log.NumPoints();
  for (int k : keep)
    if (k < 1 || k > K)
      Throw(option, " ", k, ": ", log.source.string(), " has ", K, K == 1 ? " point" : " points",
            " per row; give numbers from 1 to ", K);
  if (keep.size() == 2) Throw(option, " gives 2 points; give one point or at least 3");
  for (size_t a = 0; a < keep.size(); ++a)
    for (size_t b = 0; b < a; ++b)
      if (keep[a] == keep[b])
        Throw(option, " names point ", keep[a], " twice; each point counts once (a repeated one would shrink the "
              "sigmas as if measured again)");
  for (auto& m : out.rows) {
    std::vector<Vec3> all{m.p_meas};
    all.insert(all.end(), m.other_points.begin(), m.other_points.end());
    m.p_meas = all[keep[0] - 1];
    m.other_points.clear();
    for (size_t i = 1; i < keep.size(); ++i) m.other_points.push_back(all[keep[i] - 1]);
  }
  return out;
}

const char* Name(PostureGroup g) {
  switch (g) {
    case PostureGroup::kRepeated: return "repeated";
    case PostureGroup::kNewInRange: return "new_in_range";
    case PostureGroup::kOutOfRange: return "out_of_range";
  }
  return "";
}

std::vector<PostureGroup> PostureGroups(const RobotLog& fitted, const RobotLog& other, double tolerance) {
  std::vector<PostureGroup> g;
  if (fitted.rows.empty()) return std::vector<PostureGroup>(other.rows.size(), PostureGroup::kOutOfRange);
  const int n = fitted.rows.front().q.size();
  Eigen::VectorXd lo = fitted.rows.front().q, hi = lo;
  for (const auto& r : fitted.rows) lo = lo.cwiseMin(r.q), hi = hi.cwiseMax(r.q);
  for (const auto& r : other.rows) {
    bool repeated = false;
    for (const auto& f : fitted.rows)
      if (f.q.size() == n && r.q.size() == n && (f.q - r.q).cwiseAbs().maxCoeff() <= tolerance) repeated = true;
    bool inside = r.q.size() == n;
    for (int j = 0; j < n && inside; ++j) inside = r.q[j] >= lo[j] && r.q[j] <= hi[j];
    g.push_back(repeated ? PostureGroup::kRepeated : inside ? PostureGroup::kNewInRange : PostureGroup::kOutOfRange);
  }
  return g;
}

std::vector<RobotMeasurement> ReadRobotMeasurements(const std::filesystem::path& path) {
  const std::string source = "measurement file " + path.string();
  YAML::Node root;
  try {
    root = LoadYaml(ReadTextFile(path), source);
  } catch (const YAML::Exception& e) {
    Throw(source, ": not valid YAML: ", e.what());
  }
  std::vector<RobotMeasurement> out;
  try {
    if (root.IsMap() && root["measurements"]) {
      const YAML::Node list = root["measurements"];
      if (!list.IsSequence() || list.size() == 0) Throw(source, ": 'measurements' must be a non-empty list");
      for (size_t i = 0; i < list.size(); ++i) {
        const YAML::Node e = list[i];
        const std::string where =
            source + " measurement " + std::to_string(i + 1) + " (line " + std::to_string(e.Mark().line + 1) + ")";
        RobotMeasurement m;
        std::vector<double> q;
        if (e["q_rad"] && e["q_deg"])
          Throw(where, ": both 'q_rad' and 'q_deg' are given; give the joint values once");
        if (e["q_rad"]) {
          q = ReadList(e["q_rad"], where + " q_rad");
        } else if (e["q_deg"]) {
          q = ReadList(e["q_deg"], where + " q_deg");
          for (double& v : q) v *= kDeg;
        } else {
          Throw(where, ": missing 'q_rad' (or 'q_deg'), the joint values");
        }
        m.q = Eigen::Map<Eigen::VectorXd>(q.data(), static_cast<int>(q.size()));
        if (!e["position_m"]) Throw(where, ": missing 'position_m' [x, y, z]");
        const auto p = ReadList(e["position_m"], where + " position_m");
        if (p.size() != 3) Throw(where, ": position_m must have 3 numbers, has ", p.size());
        m.p_meas = Vec3(p[0], p[1], p[2]);
        if (e["quaternion_wxyz"]) {
          const auto v = ReadList(e["quaternion_wxyz"], where + " quaternion_wxyz");
          if (v.size() != 4) Throw(where, ": quaternion_wxyz must have 4 numbers");
          const Eigen::Quaterniond qq(v[0], v[1], v[2], v[3]);
          if (!IsUnitQuaternion(qq)) Throw(where, ": quaternion_wxyz has norm ", qq.norm(), ", expected 1");
          m.R_meas_tool = qq.normalized().toRotationMatrix();
        }
        m.line = e.Mark().line + 1;
        m.source = where;
        out.push_back(m);
      }
    } else if (root.IsMap() && root.size() > 0) {
      for (const auto& kv : root) {
        const std::string where = source + " measurement " + std::to_string(out.size() + 1) + " ('" +
                                  kv.first.as<std::string>() + "', line " + std::to_string(kv.first.Mark().line + 1) +
                                  ")";
        const YAML::Node e = kv.second;
        if (!e.IsMap() || !e["pose"] || !e["target_joints"])
          Throw(where,
                ": expected 'pose' and 'target_joints' (industrial_calibration layout) or a top-level "
                "'measurements' list (mcms layout)");
        if (e["camera_joints"] && e["camera_joints"].size() > 0)
          Throw(where, ": camera_joints is not empty; only a static measuring system is supported");
        const auto q = ReadList(e["target_joints"], where + " target_joints");
        RobotMeasurement m;
        m.q = Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<int>(q.size()));
        const Pose T = ParsePoseNode(e["pose"], where);
        m.p_meas = T.t;
        m.R_meas_tool = T.R;
        m.line = kv.first.Mark().line + 1;
        m.source = where;
        out.push_back(m);
      }
    } else {
      Throw(source, ": expected a 'measurements' list or a map of industrial_calibration measurements");
    }
  } catch (const YAML::Exception& e) {
    Throw(source, ": ", e.what());
  }
  return out;
}

void WriteRobotMeasurements(const std::filesystem::path& path, const std::vector<RobotMeasurement>& ms) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap << YAML::Key << "measurements" << YAML::Value << YAML::BeginSeq;
  for (const auto& m : ms) {
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "q_rad" << YAML::Value << YAML::Flow << std::vector<double>(m.q.data(), m.q.data() + m.q.size());
    out << YAML::Key << "position_m" << YAML::Value << YAML::Flow
        << std::vector<double>{m.p_meas.x(), m.p_meas.y(), m.p_meas.z()};
    if (m.R_meas_tool) {
      Eigen::Quaterniond q(*m.R_meas_tool);
      if (q.w() < 0) q.coeffs() *= -1.0;
      out << YAML::Key << "quaternion_wxyz" << YAML::Value << YAML::Flow
          << std::vector<double>{q.w(), q.x(), q.y(), q.z()};
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  const std::string text = std::string(out.c_str()) + "\n";
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

void CheckRobotMeasurements(const RobotModel& robot, const std::vector<RobotMeasurement>& ms, const char* who) {
  if (ms.empty()) Throw(who, ": no measurements given; give joint values and measured positions");
  const bool six = ms[0].R_meas_tool.has_value();
  for (size_t i = 0; i < ms.size(); ++i) {
    const RobotMeasurement& m = ms[i];
    // "<who>: measurement 5" plus where it was read from, when known.
    const std::string at = m.source.empty() ? std::string() : " (" + m.source + ")";
    if (m.q.size() != robot.NumJoints())
      Throw(who, ": measurement ", i + 1, at, " has ", m.q.size(), " joint values but robot '", robot.Name(), "' has ",
            robot.NumJoints(), " joints; give one value per joint");
    std::string why;
    if (!robot.WithinLimits(m.q, &why))
      Throw(who, ": measurement ", i + 1, at, ": ", why, "; remove the measurement or correct the joint limits");
    if (!m.p_meas.allFinite()) Throw(who, ": measurement ", i + 1, at, " has a non-finite position");
    for (const Vec3& p : m.other_points)
      if (!p.allFinite()) Throw(who, ": measurement ", i + 1, at, " has a non-finite point");
    if (m.NumPoints() != ms[0].NumPoints())
      Throw(who, ": measurement ", i + 1, at, " has ", m.NumPoints(), " points but measurement 1 has ",
            ms[0].NumPoints(), "; every measurement measures the same points");
    if (m.R_meas_tool.has_value() != six)
      Throw(who, ": measurement ", i + 1, " is ", m.R_meas_tool ? "6-D" : "3-D", " but measurement 1 is ",
            six ? "6-D" : "3-D", "; give orientations for all measurements or for none");
  }
}

Pose InitialBaseGuess(const RobotModel& robot, const std::vector<RobotMeasurement>& measurements) {
  CheckRobotMeasurements(robot, measurements, "robot calibration (starting registration)");
  const int n = static_cast<int>(measurements.size());
  if (n < 3) Throw("InitialBaseGuess: ", n, " measurements; at least 3 non-collinear positions are needed");
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (int i = 0; i < n; ++i) {
    src.col(i) = robot.T_base_tool(measurements[i].q).t;
    dst.col(i) = measurements[i].p_meas;
  }
  const Vec3 cs = src.rowwise().mean(), cd = dst.rowwise().mean();
  double spread = 0.0;
  const Pose T = RigidFit(src, dst, &spread);
  if (!(spread >= 1e-9)) {
    const double spread_meas = (dst.colwise() - cd).norm() / std::sqrt(n);
    const double spread_model = (src.colwise() - cs).norm() / std::sqrt(n);
    const char* why = spread_meas < 1e-6    ? "every measured position is the same (the same row repeated?)"
                      : spread_model < 1e-6 ? "the logged joints put the tool at the same place in every row (are "
                                              "the joint columns filled, in the unit their headers give?)"
                                            : "the measured positions, or the tool positions of the logged "
                                              "joints, lie on one line";
    Throw("the starting registration cannot be found: ", why,
          "; give measurements spread over the workspace, or a starting base transform");
  }
  return T;
}

}  // namespace mcms
