#include "model/robot_measurements.h"

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

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string JointName(const RobotModel& robot, int i) {
  const std::string& n = robot.Joints()[i].name;
  return n.empty() ? "joint " + std::to_string(i + 1) : n;
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
    if (log.has_temperature && !(r.temperature_c >= kMinTemperatureC && r.temperature_c <= kMaxTemperatureC))
      Throw(log.Where(i), ": temperature_c is ", r.temperature_c, "; expected ", kMinTemperatureC, " to ",
            kMaxTemperatureC, " deg C");
    if (log.has_payload && !(std::isfinite(r.payload_kg) && r.payload_kg >= 0 && r.payload_kg <= kMaxMassKg))
      Throw(log.Where(i), ": payload_kg is ", r.payload_kg, "; expected a finite mass from 0 to ", kMaxMassKg, " kg");
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

// ---- plausibility ------------------------------------------------------------------

namespace {

// A mistyped row: a measured position far outside where the others lie (a coordinate of
// 1e308, one row in millimetres). Robust: distances from the componentwise median,
// against their median; a row beyond 100 times that (and 10 m) is named.
void CheckOutlyingRow(const RobotLog& log) {
  const int N = log.rows.size();
  Vec3 med;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> c(N);
    for (int i = 0; i < N; ++i) c[i] = log.rows[i].p_meas[k];
    med[k] = SelectedMedian(c);
  }
  std::vector<double> d(N);
  for (int i = 0; i < N; ++i) d[i] = (log.rows[i].p_meas - med).norm();
  std::vector<double> sorted = d;
  const double typical = SelectedMedian(sorted);
  for (int i = 0; i < N; ++i)
    if (d[i] > std::max(100.0 * typical, 10.0))
      Throw(log.Where(i), ": the measured position (", Num4(log.rows[i].p_meas.x()), ", ", Num4(log.rows[i].p_meas.y()),
            ", ", Num4(log.rows[i].p_meas.z()), ") m lies ",
            std::isfinite(d[i]) ? Num4(d[i]) + " m" : std::string("absurdly far"),
            " from the log's median position, where the other rows lie within about ", Num4(typical),
            " m: a mistyped row, or another unit than metres?");
}

// The same measurement twice (identical joints and position to the last digit, which two
// real measurements never are) would count it twice and halve its variance.
void CheckDuplicateRows(const RobotLog& log) {
  std::vector<size_t> order(log.rows.size());
  std::iota(order.begin(), order.end(), 0);
  const auto key = [&](size_t i) {
    const RobotMeasurement& r = log.rows[i];
    std::vector<double> k(r.q.data(), r.q.data() + r.q.size());
    k.insert(k.end(), {r.p_meas.x(), r.p_meas.y(), r.p_meas.z()});
    return k;
  };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key(a) < key(b); });
  size_t a = 0, b = order.size();  // the duplicate pair whose later row comes first
  for (size_t k = 1; k < order.size(); ++k)
    if (key(order[k - 1]) == key(order[k]) && std::max(order[k - 1], order[k]) < b)
      a = std::min(order[k - 1], order[k]), b = std::max(order[k - 1], order[k]);
  if (b < order.size()) {
    const std::string first = log.Where(a);
    const std::string prefix = log.source.empty() ? std::string("robot log") : log.source.string();
    const bool same_file = first.rfind(prefix + " ", 0) == 0;
    Throw(log.Where(b), " repeats ", same_file ? first.substr(prefix.size() + 1) : first,
          " exactly (the same joints and measured position): a duplicated row would count one measurement "
          "twice; remove the duplicates (repeated visits of a pose measure a new position each time)");
  }
}

// The best similarity from the model's tool positions src to the measured ones dst (3 x N):
// its scale with a rotation, with a rotation or reflection, whether the best is a
// reflection, and (optional) the RMS residual of the rotation's fit relative to the
// measured positions' spread.
void SimilarityScale(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, double* scale, double* scale_any,
                     bool* mirrored, double* relative_rms) {
  const int N = src.cols();
  const Eigen::Matrix3Xd a = src.colwise() - src.rowwise().mean(), b = dst.colwise() - dst.rowwise().mean();
  const double var_src = std::max(a.squaredNorm() / N, 1e-300), var_dst = b.squaredNorm() / N;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(b * a.transpose() / N, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d d(1, 1, 1);
  *mirrored = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0;
  if (*mirrored) d[2] = -1;
  *scale = svd.singularValues().dot(d) / var_src;
  *scale_any = svd.singularValues().sum() / var_src;  // rotation or reflection
  if (relative_rms) {
    // Umeyama: residual variance var_dst - (sum d_k s_k)^2 / var_src.
    const double sd = svd.singularValues().dot(d);
    *relative_rms = std::sqrt(std::max(0.0, var_dst - sd * sd / var_src) / std::max(var_dst, 1e-300));
  }
}

// Measured positions in another unit than metres, a robot description of another size,
// swapped axes, or joints that do not move the tool: the best similarity between the tool
// positions the robot's model gives for the logged joints and the measured ones has a
// scale far from 1 or needs a reflection.
void CheckScale(const RobotModel& robot, const RobotLog& log) {
  const int N = log.rows.size();
  Eigen::Matrix3Xd src(3, N), dst(3, N);
  for (int i = 0; i < N; ++i) {
    src.col(i) = robot.T_base_tool(log.rows[i].q).t;
    dst.col(i) = log.rows[i].p_meas;
  }
  const Eigen::Matrix3Xd a = src.colwise() - src.rowwise().mean(), b = dst.colwise() - dst.rowwise().mean();
  const double var_src = a.squaredNorm() / N, var_dst = b.squaredNorm() / N;
  const std::string src_name = log.source.empty() ? std::string("robot log") : log.source.string();
  if (!(var_src > 1e-8)) {
    if (var_dst > 1e-6)
      Throw(src_name,
            ": the logged joints put the tool at the same place in every row (within 0.1 mm), but the "
            "measured positions spread over ",
            Num4(std::sqrt(var_dst)), " m (RMS): are the joint columns filled, and in the unit their headers give?");
    Throw(src_name,
          ": neither the logged joints nor the measured positions move (every row measures the same "
          "place): measurements spread over the workspace are needed");
  }
  double scale = 0, scale_any = 0;
  bool mirrored = false;
  SimilarityScale(src, dst, &scale, &scale_any, &mirrored, nullptr);
  if (scale > 0.8 && scale < 1.25) return;
  if (mirrored && scale_any > 0.8 && scale_any < 1.25)
    Throw(src_name, ": the measured positions are a mirror image of where robot '", robot.Name(),
          "' puts its tool at the logged joints (a rotation fits them only at scale ", Num4(scale),
          ", a reflection at ", Num4(scale_any),
          "): two of the x, y, z columns swapped, or one axis's sign flipped?");
  // One joint in another unit than its header says (a prismatic joint in mm, radians under
  // a _deg header): the positions fit once that joint's values are rescaled.
  const int n = robot.NumJoints();
  const struct {
    double factor;
    const char* hint;
  } kUnits[] = {{1e-3, "millimetres where metres are read?"},
                {1e3, "metres where millimetres are read?"},
                {180.0 / std::numbers::pi, "radians under a _deg header?"},
                {std::numbers::pi / 180.0, "degrees where radians are read?"}};
  for (int j = 0; j < n; ++j)
    for (const auto& u : kUnits) {
      Eigen::Matrix3Xd s2(3, N);
      bool inside = true;  // a reading rescaled beyond the joint's range is not what was meant
      for (int i = 0; i < N && inside; ++i) {
        Eigen::VectorXd q = log.rows[i].q;
        q[j] *= u.factor;
        inside = robot.WithinLimits(q, nullptr);  // the forward kinematics' own (strict) test
        if (inside) s2.col(i) = robot.T_base_tool(q).t;
      }
      if (!inside) continue;
      double sc = 0, sc_any = 0, rel = 1;
      bool mir = false;
      SimilarityScale(s2, dst, &sc, &sc_any, &mir, &rel);
      if (sc > 0.8 && sc < 1.25 && rel < 0.05)
        Throw(src_name, ": the measured positions fit robot '", robot.Name(), "' once joint ", JointName(robot, j),
              "'s logged values are taken ", Num4(u.factor), " times as large (", u.hint,
              "); give each joint in the unit its column's header says");
    }
  const std::string unit = LengthUnitHint(scale);
  Throw(src_name, ": the measured positions are ", Num4(scale), " times as far apart as robot '", robot.Name(),
        "' puts its tool at the logged joints", unit,
        "; give the positions in metres, and the robot description the log was measured with (--robot)");
}

// Points of one rigid body keep their mutual distances: per pair, each row's distance
// against the median over the rows; a row off by more than 1 mm and 10 times the pairs'
// robust scatter is named.
void CheckRigid(const RobotLog& log) {
  const int K = log.NumPoints(), N = log.rows.size();
  if (K < 2) return;
  std::vector<std::string> bad;
  double worst = 0;
  std::vector<double> dev_row(N, 0.0);
  std::vector<double> all_dev;
  for (int a = 0; a < K; ++a)
    for (int b = a + 1; b < K; ++b) {
      std::vector<double> d(N);
      for (int i = 0; i < N; ++i) d[i] = (log.rows[i].Point(a) - log.rows[i].Point(b)).norm();
      std::vector<double> s = d;
      const double med = SelectedMedian(s);
      for (int i = 0; i < N; ++i) {
        dev_row[i] = std::max(dev_row[i], std::abs(d[i] - med));
        all_dev.push_back(std::abs(d[i] - med));
      }
    }
  const double mad = SelectedMedian(all_dev);
  const double limit = std::max(1e-3, 10.0 * 1.4826 * mad);
  for (int i = 0; i < N; ++i)
    if (dev_row[i] > limit) {
      if (bad.size() < 8) bad.push_back(std::to_string(log.rows[i].line > 0 ? log.rows[i].line : i + 1));
      worst = std::max(worst, dev_row[i]);
    }
  if (bad.empty()) return;
  std::string rows;
  for (size_t k = 0; k < bad.size(); ++k) rows += (k ? ", " : "") + bad[k];
  Throw(log.source.empty() ? std::string("robot log") : log.source.string(), ": the ", K,
        " points are not one rigid body: their mutual distances change by up to ", Num4(worst * 1e3), " mm on ",
        log.rows.front().line > 0 ? "line" : "row", bad.size() > 1 ? "s " : " ", rows,
        " (elsewhere within ", Num4(limit * 1e3), " mm); a marker lost or swapped, or points of different bodies?");
}

void CheckRowsFitTheRobot(const RobotModel& robot, const RobotLog& log);  // below

}  // namespace

// Measured positions that never move while the joints move the tool (a position column
// filled once and copied down): named before the rows are compared with each other.
void CheckPositionsMove(const RobotModel& robot, const RobotLog& log) {
  for (const std::string& st : log.Stations()) {
    std::vector<Vec3> tool, meas;
    for (const auto& r : log.rows)
      if (r.station == st) tool.push_back(robot.T_base_tool(r.q).t), meas.push_back(r.p_meas);
    if (meas.size() < 2) continue;
    double spread_meas = 0, spread_tool = 0;
    for (size_t i = 1; i < meas.size(); ++i) {
      spread_meas = std::max(spread_meas, (meas[i] - meas[0]).norm());
      spread_tool = std::max(spread_tool, (tool[i] - tool[0]).norm());
    }
    if (spread_meas < 1e-6 && spread_tool > 1e-4)
      Throw(log.source.empty() ? std::string("robot log") : log.source.string(),
            st.empty() ? std::string() : std::string(" station ").append(st),
            ": the measured positions do not move (every row measures the same point within 1 um) while the "
            "logged joints move the tool over ",
            Num4(spread_tool), " m: are the position columns filled per row?");
  }
}

void CheckRobotLogPlausible(const RobotLog& log, const RobotModel& robot) {
  CheckRobotLog(log, robot);
  CheckPositionsMove(robot, log);
  CheckDuplicateRows(log);
  CheckRigid(log);
  // The checks against one placement of the instrument: per station where the log has them.
  const std::vector<std::string> stations = log.Stations();
  for (const std::string& st : stations) {
    RobotLog part;
    const RobotLog* one = &log;
    if (stations.size() > 1) {
      part = log;
      part.rows.clear();
      for (const auto& r : log.rows)
        if (r.station == st) part.rows.push_back(r);
      if (part.rows.size() < 4) continue;  // too few to test; placing it names it
      one = &part;
    }
    CheckOutlyingRow(*one);
    CheckScale(robot, *one);
    CheckRowsFitTheRobot(robot, *one);
  }
}

namespace {

Eigen::Matrix3Xd PointsOfRow(const RobotLog& log, int i) {
  const int K = log.rows[i].NumPoints();
  Eigen::Matrix3Xd P(3, K);
  for (int k = 0; k < K; ++k) P.col(k) = log.rows[i].Point(k);
  return P;
}

// Kabsch: the pose mapping `ref` (body frame) onto `P` (meas frame), least squares.
Pose Align(const Eigen::Matrix3Xd& ref, const Eigen::Matrix3Xd& P) { return RigidFit(ref, P); }

// Measured orientations (qw, qx, qy, qz) against the robot, once the positions fit: the
// tool's rotation on the flange, (R_meas_base R_base_flange)^T R_meas_tool, is one rotation
// in every row, to a fraction of a degree for any robot its description fits. Spread over
// tens of degrees, they are not the robot's tool orientations: read scalar-last (the same
// four numbers as x, y, z, w), the usual mix-up, is said when that makes them agree.
// The median angle of each row's rotation from their chordal mean is compared with 10 deg.
double MedianSpreadDeg(const std::vector<Mat3>& R) {
  Mat3 sum = Mat3::Zero();
  for (const Mat3& r : R) sum += r;
  Eigen::JacobiSVD<Mat3> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) D(2, 2) = -1;
  const Mat3 mean = svd.matrixU() * D * svd.matrixV().transpose();
  std::vector<double> a;
  for (const Mat3& r : R) a.push_back(Eigen::AngleAxisd(mean.transpose() * r).angle());
  return SelectedMedian(a) * 180 / std::numbers::pi;
}

void CheckOrientationsFitTheRobot(const RobotModel& robot, const RobotLog& log, const std::vector<Pose>& flange,
                                  const Pose& T) {
  std::vector<Mat3> tool, tool_xyzw;
  for (size_t i = 0; i < log.rows.size(); ++i) {
    if (!log.rows[i].R_meas_tool) return;
    const Mat3 to_flange = (T.R * flange[i].R).transpose();
    tool.push_back(to_flange * *log.rows[i].R_meas_tool);
    tool_xyzw.push_back(to_flange * RotationReadScalarLast(Eigen::Quaterniond(*log.rows[i].R_meas_tool)));
  }
  if (tool.size() < 4) return;
  const double spread = MedianSpreadDeg(tool);
  if (!(spread > 10)) return;
  const double spread_xyzw = MedianSpreadDeg(tool_xyzw);
  Throw(log.source.empty() ? std::string("robot log") : log.source.string(), ": the measured orientations (qw, qx, ",
        "qy, qz) do not follow robot '", robot.Name(), "': the tool's rotation on the flange they imply varies by ",
        Num4(spread), " deg (median from its mean) where a robot its description fits keeps it within a degree",
        spread_xyzw < 2 ? "; read scalar-last they agree to " + Num4(spread_xyzw) +
                              " deg: quaternions x, y, z, w under qw, qx, qy, qz? expected qw, qx, qy, qz (scalar first)"
                        : std::string("; are the orientations those of the tool whose positions the log gives?"));
}

// Rows of another layout among the others (x and y exchanged in some rows, a row in
// another unit): once the scale is right, the best rigid registration and tool position
// leave residuals of the size of the motion itself, where any robot the description
// fits (every DH term off, sag, backlash) leaves a few mm. Named when the RMS is beyond
// 10 % of the positions' spread and 20 mm, with the row farthest off.
void CheckRowsFitTheRobot(const RobotModel& robot, const RobotLog& log) {
  const int N = log.rows.size();
  if (N < 4) return;
  // A robot measured while it moves (joint velocities known): a clock offset between the
  // logs, an effect the audit names, misplaces rows by the speed times the offset.
  for (const RobotMeasurement& r : log.rows)
    if (r.qdot.size() > 0) return;
  std::vector<Pose> flange(N);
  Eigen::Matrix3Xd dst(3, N), src(3, N);
  for (int i = 0; i < N; ++i) flange[i] = robot.T_base_flange(log.rows[i].q), dst.col(i) = log.rows[i].p_meas;
  Vec3 tool = robot.T_flange_tool().t;
  Pose T;  // T_meas_base
  for (int round = 0; round < 20; ++round) {  // registration and tool point in turn
    for (int i = 0; i < N; ++i) src.col(i) = flange[i] * tool;
    T = Align(src, dst);
    Vec3 sum = Vec3::Zero();
    for (int i = 0; i < N; ++i) sum += flange[i].R.transpose() * (T.R.transpose() * (dst.col(i) - T.t) - flange[i].t);
    tool = sum / N;
  }
  for (int i = 0; i < N; ++i) src.col(i) = flange[i] * tool;
  T = Align(src, dst);
  double ss = 0, worst = -1;
  int far = 0;
  for (int i = 0; i < N; ++i) {
    const double e = (T * Vec3(src.col(i)) - dst.col(i)).norm();
    ss += e * e;
    if (e > worst) worst = e, far = i;
  }
  const double rms = std::sqrt(ss / N);
  const double spread = std::sqrt((dst.colwise() - dst.rowwise().mean()).squaredNorm() / N);
  if (!(rms > std::max(0.1 * spread, 0.02))) {
    CheckOrientationsFitTheRobot(robot, log, flange, T);
    return;
  }
  Throw(log.source.empty() ? std::string("robot log") : log.source.string(),
        ": with the best registration and tool position, robot '", robot.Name(),
        "' explains the measured positions only to ", Num4(1e3 * rms), " mm RMS while they spread over ",
        Num4(1e3 * spread), " mm (the row farthest off, ", log.Where(far), ", by ", Num4(1e3 * worst),
        " mm); a robot its description fits leaves a few mm: check the rows' columns (x and y swapped in some?) and "
        "units, and --robot");
}

}  // namespace

RigidBody FitRigidBody(const RobotLog& log) {
  const int K = log.NumPoints(), N = log.rows.size();
  if (K < 3) Throw("FitRigidBody: ", K, " points per row; a rigid body's pose needs at least 3");
  // The mean shape over the rows, in the first row's orientation, centred.
  Eigen::Matrix3Xd ref = PointsOfRow(log, 0);
  ref = ref.colwise() - ref.rowwise().mean().eval();
  for (int pass = 0; pass < 3; ++pass) {
    Eigen::Matrix3Xd mean = Eigen::Matrix3Xd::Zero(3, K);
    for (int i = 0; i < N; ++i) {
      const Pose Ti = Align(ref, PointsOfRow(log, i)).Inverse();
      mean += (Ti.R * PointsOfRow(log, i)).colwise() + Ti.t;
    }
    mean /= N;
    const Pose T0 = Align(mean, PointsOfRow(log, 0));
    const Vec3 c0 = PointsOfRow(log, 0).rowwise().mean();
    ref = (T0.R * mean).colwise() + (T0.t - c0);
  }
  std::vector<Vec3> shape;
  for (int k = 0; k < K; ++k) shape.push_back(ref.col(k));
  // Points on one line fix no rotation about it: not a pose.
  Eigen::JacobiSVD<Mat3> svd(Mat3(ref * ref.transpose()));
  if (!(svd.singularValues()[1] > 1e-6 * svd.singularValues()[0]) || !(std::sqrt(svd.singularValues()[1]) > 1e-4))
    Throw(log.source.empty() ? std::string("robot log") : log.source.string(), ": the ", K,
          " points of the rigid body lie on one line (spread ", std::sqrt(std::max(0.0, svd.singularValues()[1])) * 1e3,
          " mm across it); a body's pose needs points spread in two directions (give one point, or points not in a "
          "line)");
  return RigidBodyPoses(log, shape);
}

RigidBody RigidBodyPoses(const RobotLog& log, const std::vector<Vec3>& points_body) {
  const int K = points_body.size();
  Eigen::Matrix3Xd ref(3, K);
  for (int k = 0; k < K; ++k) ref.col(k) = points_body[k];
  RigidBody body;
  body.points_body = points_body;
  for (size_t i = 0; i < log.rows.size(); ++i) {
    if (log.rows[i].NumPoints() != K)
      Throw(log.Where(i), ": ", log.rows[i].NumPoints(), " points, but the rigid body has ", K);
    const Eigen::Matrix3Xd P = PointsOfRow(log, i);
    const Pose T = Align(ref, P);
    body.T_meas_body.push_back(T);
    const Eigen::Matrix3Xd pred = (T.R * ref).colwise() + T.t;
    body.fit_rms_m.push_back(std::sqrt((pred - P).squaredNorm() / K));
  }
  return body;
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
