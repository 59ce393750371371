#include "fusion/sensor_logs.h"

#include "model/robot_measurements.h"

#include <numbers>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <set>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/error.h"
#include "core/limits.h"
#include "core/io.h"
#include "core/yaml.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
const char* const kAxes[6] = {"rx", "ry", "rz", "px", "py", "pz"};

// ReadCsv plus the checks every log shares: a file with no header names line 1, one with
// a header but no data names the header's line. Returns the table and the header's line.
CsvTable ReadLog(const fs::path& path, const std::string& what, int* header_line) {
  const std::string text = ReadTextFile(path);
  std::istringstream in(text);
  std::string line;
  int lineno = 0, header = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos) continue;
    header = lineno;
    break;
  }
  if (header == 0) Throw(path.string(), " line 1: empty file, expected a ", what, " CSV with a header row");
  CsvTable t = ReadCsv(path);
  if (t.rows.empty())
    Throw(path.string(), " line ", header, ": header but no data rows, expected at least one ", what, " row");
  *header_line = header;
  return t;
}

// The column `base`_<unit> for one of the given units: its index and the unit's scale to SI.
// InputError naming the file and the expected names when none or several are present.
std::pair<int, double> UnitColumn(const CsvTable& t, int header_line, const std::string& base,
                                  const std::vector<std::pair<std::string, double>>& units) {
  std::optional<std::pair<int, double>> found;
  std::string names, found_name;
  for (const auto& [suffix, scale] : units) {
    const std::string name = base + "_" + suffix;
    names += (names.empty() ? "'" : " or '") + name + "'";
    if (!t.HasColumn(name)) continue;
    if (found) Throw(t.source.string(), " line ", header_line, ": give only one of '", found_name, "' and '", name, "'");
    found = std::make_pair(t.Column(name), scale);
    found_name = name;
  }
  if (!found) Throw(t.source.string(), " line ", header_line, ": missing column ", names, " in the header");
  return *found;
}

void CheckIncreasing(const CsvTable& t, size_t row, double time, double previous) {
  if (row > 0 && !(time > previous))
    Throw(t.source.string(), " line ", t.line_of_row[row], ": time_s ", time,
          " does not increase (the previous row, line ", t.line_of_row[row - 1], ", has ", previous,
          "); time stamps must be strictly increasing");
}

// ---- YAML: every error names the setup file, the line and the key. ----
class Yaml {
 public:
  explicit Yaml(std::string source) : source_(std::move(source)) {}

  template <typename... Parts>
  [[noreturn]] void Fail(const YAML::Node& at, const Parts&... parts) const {
    if (at.IsDefined() && at.Mark().line >= 0) Throw(source_, " line ", at.Mark().line + 1, ": ", parts...);
    Throw(source_, ": ", parts...);
  }

  void Keys(const YAML::Node& map, const std::set<std::string>& allowed, const std::string& where) const {
    if (!map.IsMap()) Fail(map, where, " must be a map of key: value");
    for (const auto& kv : map) {
      const std::string key = kv.first.as<std::string>();
      if (allowed.count(key)) continue;
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      Fail(kv.first, where, ": unknown key '", key, "' (expected one of: ", list, ")");
    }
  }

  double Number(const YAML::Node& n, const std::string& what) const {
    double v = 0.0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      Fail(n, what, " must be a number");
    }
    if (!std::isfinite(v)) Fail(n, what, " must be finite");
    return v;
  }

  std::vector<double> Numbers(const YAML::Node& n, size_t count, const std::string& what) const {
    if (!n.IsSequence() || n.size() != count) Fail(n, what, " must be a list of ", count, " numbers");
    std::vector<double> v;
    for (size_t i = 0; i < count; ++i) v.push_back(Number(n[i], what));
    return v;
  }

  // key_<unit> for one of the units, scaled to SI; nullopt when absent.
  std::optional<std::pair<YAML::Node, double>> WithUnit(const YAML::Node& map, const std::string& key,
                                                        const std::vector<std::pair<std::string, double>>& units,
                                                        const std::string& where) const {
    std::optional<std::pair<YAML::Node, double>> found;
    std::string found_key;
    for (const auto& [suffix, scale] : units) {
      const std::string k = key + "_" + suffix;
      if (!map[k]) continue;
      if (found) Fail(map[k], where, ": give only one of '", found_key, "' and '", k, "'");
      found = std::make_pair(map[k], scale);
      found_key = k;
    }
    return found;
  }

  Mat3 Rotation(const YAML::Node& map, const std::string& where) const {
    const YAML::Node n = map["quaternion_wxyz"];
    if (!n) Fail(map, where, ": missing 'quaternion_wxyz: [w, x, y, z]'");
    const auto q = Numbers(n, 4, where + ".quaternion_wxyz");
    const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (!IsUnitQuaternion(quat))
      Fail(n, where, ".quaternion_wxyz must have unit norm, has norm ", quat.norm());
    return quat.normalized().toRotationMatrix();
  }

  Pose Transform(const YAML::Node& map, const std::string& where, const std::set<std::string>& extra_keys) const {
    std::set<std::string> keys = {"translation_m", "quaternion_wxyz"};
    keys.insert(extra_keys.begin(), extra_keys.end());
    Keys(map, keys, where);
    const YAML::Node t = map["translation_m"];
    if (!t) Fail(map, where, ": missing 'translation_m: [x, y, z]'");
    const auto v = Numbers(t, 3, where + ".translation_m");
    Pose T;
    T.R = Rotation(map, where);
    T.t = Vec3(v[0], v[1], v[2]);
    return T;
  }

 private:
  std::string source_;
};

const std::vector<std::pair<std::string, double>> kAngle = {{"rad", 1.0}, {"deg", kDeg}};

double NonNegative(const Yaml& y, const YAML::Node& n, double scale, const std::string& what) {
  const double v = y.Number(n, what) * scale;
  if (v < 0) y.Fail(n, what, " must be >= 0");
  return v;
}

FusionSetup ParseRoot(const YAML::Node& root, const Yaml& y, const fs::path& source, const fs::path& base_dir) {
  FusionSetup s;
  s.source = source;
  y.Keys(root,
         {"robot", "base_link", "tip_link", "T_base_rig", "T_flange_target", "inclinometer", "robot_accuracy",
          "kalman", "consistency_significance"},
         "setup");
  if (const YAML::Node r = root["robot"]) {
    fs::path p = r.as<std::string>();
    if (p.is_relative()) p = base_dir / p;
    if (!fs::exists(p)) y.Fail(r, "robot: file ", p.string(), " does not exist");
    if (fs::is_directory(p))
      y.Fail(r, "robot: ", p.string(), " is a folder; expected the robot's description file (YAML or URDF)");
    // A URDF's chain: the setup's base_link and tip_link, as the robot commands' --base-link
    // and --tip-link (named so in the messages: fuse has no such options).
    ChainSelection chain;
    if (root["base_link"]) chain.base_link = root["base_link"].as<std::string>();
    if (root["tip_link"]) chain.tip_link = root["tip_link"].as<std::string>();
    try {
      s.robot = RobotModel::Read(p, chain);
    } catch (const InputError& e) {
      std::string w = e.what();
      for (const auto& [option, key] : {std::pair<std::string, std::string>{"--tip-link", "tip_link (a key of the setup)"},
                                        {"--base-link", "base_link (a key of the setup)"}})
        for (size_t at = w.find(option); at != std::string::npos; at = w.find(option, at + key.size()))
          w.replace(at, option.size(), key);
      Throw(source.string(), ", robot: ", w);
    }
  } else {
    if (root["base_link"] || root["tip_link"]) y.Fail(root, "base_link and tip_link pick the chain of a URDF given as robot:");
    s.robot = RobotModel::Default();
  }
  // The fusion estimates T_base_flange; the target's mounting is T_flange_target. The
  // flange of a DH table is its last frame (a tool it names is not the flange); that of a
  // URDF is its tip link, reached through the fixed joints after the last moving one
  // (issue 53: a DH table written as a URDF puts its flange frame there, the last moving
  // link's frame sitting on the joint's axis).
  if (!s.robot.Urdf()) s.robot.SetT_flange_tool(Pose::Identity());

  const YAML::Node br = root["T_base_rig"];
  if (!br) y.Fail(root, "missing 'T_base_rig' (the rig frame registered in the robot base)");
  s.T_base_rig = y.Transform(br, "T_base_rig", {"sigma_rotation_rad", "sigma_rotation_deg", "sigma_translation_m"});
  if (!(s.T_base_rig.t.norm() <= kMaxRigRangeM))
    y.Fail(br, "T_base_rig puts the rig ", s.T_base_rig.t.norm(),
           " m from the robot base, farther than a camera rig measures (", kMaxRigRangeM,
           " m): is its translation in mm? expected metres");
  if (auto n = y.WithUnit(br, "sigma_rotation", kAngle, "T_base_rig")) {
    const double sr = NonNegative(y, n->first, n->second, "T_base_rig.sigma_rotation");
    s.T_base_rig_covariance.topLeftCorner<3, 3>() = sr * sr * Mat3::Identity();
  }
  if (const YAML::Node n = br["sigma_translation_m"]) {
    const double st = NonNegative(y, n, 1.0, "T_base_rig.sigma_translation_m");
    s.T_base_rig_covariance.bottomRightCorner<3, 3>() = st * st * Mat3::Identity();
  }

  const YAML::Node ft = root["T_flange_target"];
  if (!ft) y.Fail(root, "missing 'T_flange_target' (the target's pose on the flange)");
  s.T_flange_target = y.Transform(ft, "T_flange_target", {});

  if (const YAML::Node in = root["inclinometer"]) {
    y.Keys(in, {"quaternion_wxyz", "bias_rad", "bias_deg", "sigma_rad", "sigma_deg", "period_s", "range_rad",
                "range_deg"},
           "inclinometer");
    Inclinometer& inc = s.inclinometer;
    if (in["quaternion_wxyz"]) inc.R_flange_incl = y.Rotation(in, "inclinometer");
    if (auto n = y.WithUnit(in, "bias", kAngle, "inclinometer")) {
      const auto b = y.Numbers(n->first, 2, "inclinometer.bias");
      inc.bias = Vec2(b[0], b[1]) * n->second;
    }
    if (auto n = y.WithUnit(in, "sigma", kAngle, "inclinometer")) inc.sigma = y.Number(n->first, "inclinometer.sigma") * n->second;
    if (const YAML::Node n = in["period_s"]) inc.period = y.Number(n, "inclinometer.period_s");
    if (auto n = y.WithUnit(in, "range", kAngle, "inclinometer")) inc.range = y.Number(n->first, "inclinometer.range") * n->second;
    std::string why;
    if (!inc.IsValid(&why)) y.Fail(in, "inclinometer: ", why);
  }

  if (const YAML::Node ra = root["robot_accuracy"]) {
    y.Keys(ra, {"position_sigma_m", "orientation_sigma_rad", "orientation_sigma_deg", "covariance"},
           "robot_accuracy");
    if (const YAML::Node n = ra["covariance"]) {
      if (ra["position_sigma_m"] || ra["orientation_sigma_rad"] || ra["orientation_sigma_deg"])
        y.Fail(n, "robot_accuracy: give either 'covariance' or the sigmas, not both");
      const auto v = y.Numbers(n, 36, "robot_accuracy.covariance");
      Mat6 C;
      for (int i = 0; i < 36; ++i) C(i / 6, i % 6) = v[i];
      if ((C - C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * C.cwiseAbs().maxCoeff())
        y.Fail(n, "robot_accuracy.covariance must be symmetric");
      if (Eigen::SelfAdjointEigenSolver<Mat6>(C).eigenvalues().minCoeff() < -1e-12 * C.diagonal().cwiseAbs().maxCoeff())
        y.Fail(n, "robot_accuracy.covariance must be positive semi-definite");
      s.robot_accuracy_covariance = C;
    }
    if (const YAML::Node n = ra["position_sigma_m"]) {
      const auto v = y.Numbers(n, 3, "robot_accuracy.position_sigma_m");
      for (int i = 0; i < 3; ++i) {
        if (v[i] < 0) y.Fail(n, "robot_accuracy.position_sigma_m must be >= 0");
        s.robot_accuracy_covariance(3 + i, 3 + i) = v[i] * v[i];
      }
    }
    if (auto n = y.WithUnit(ra, "orientation_sigma", kAngle, "robot_accuracy")) {
      const double so = NonNegative(y, n->first, n->second, "robot_accuracy.orientation_sigma");
      s.robot_accuracy_covariance.topLeftCorner<3, 3>() = so * so * Mat3::Identity();
    }
  }

  if (const YAML::Node k = root["kalman"]) {
    y.Keys(k,
           {"angular_acceleration_psd", "linear_acceleration_psd", "nis_gate_probability",
            "initial_angular_velocity_sigma_rad_s", "initial_linear_velocity_sigma_m_s"},
           "kalman");
    if (k["initial_angular_velocity_sigma_rad_s"])
      s.kalman.initial_angular_velocity_sigma =
          y.Number(k["initial_angular_velocity_sigma_rad_s"], "kalman.initial_angular_velocity_sigma_rad_s");
    if (k["initial_linear_velocity_sigma_m_s"])
      s.kalman.initial_linear_velocity_sigma =
          y.Number(k["initial_linear_velocity_sigma_m_s"], "kalman.initial_linear_velocity_sigma_m_s");
    if (k["angular_acceleration_psd"])
      s.kalman.angular_acceleration_psd = y.Number(k["angular_acceleration_psd"], "kalman.angular_acceleration_psd");
    if (k["linear_acceleration_psd"])
      s.kalman.linear_acceleration_psd = y.Number(k["linear_acceleration_psd"], "kalman.linear_acceleration_psd");
    if (k["nis_gate_probability"])
      s.kalman.nis_gate_probability = y.Number(k["nis_gate_probability"], "kalman.nis_gate_probability");
    std::string why;
    if (!s.kalman.IsValid(&why)) y.Fail(k, "kalman: ", why);
  }

  if (const YAML::Node c = root["consistency_significance"]) {
    s.consistency_significance = y.Number(c, "consistency_significance");
    if (!(s.consistency_significance > 0 && s.consistency_significance < 1))
      y.Fail(c, "consistency_significance must lie in (0, 1)");
  }
  return s;
}

}  // namespace

bool JointLog::Interpolate(double t, Eigen::VectorXd* q) const {
  if (samples.empty() || t < samples.front().time_s || t > samples.back().time_s) return false;
  const auto hi = std::lower_bound(samples.begin(), samples.end(), t,
                                   [](const JointSample& s, double v) { return s.time_s < v; });
  if (hi->time_s == t || hi == samples.begin()) {
    *q = hi->q;
    return true;
  }
  const auto lo = hi - 1;
  const double w = (t - lo->time_s) / (hi->time_s - lo->time_s);
  *q = (1.0 - w) * lo->q + w * hi->q;
  return true;
}

TrackerLog ReadTrackerLog(const fs::path& path) {
  int header_line = 0;
  const CsvTable t = ReadLog(path, "tracker pose", &header_line);
  const int frame = t.Column("frame"), time = t.Column("time_s"), status = t.Column("status");
  const int x = t.Column("x_m"), yc = t.Column("y_m"), z = t.Column("z_m");
  const int qw = t.Column("qw"), qx = t.Column("qx"), qy = t.Column("qy"), qz = t.Column("qz");
  int cov[6][6];
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) cov[r][c] = t.Column(std::string("cov_") + kAxes[r] + "_" + kAxes[c]);

  TrackerLog log;
  log.source = path;
  double previous = 0.0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    const int line = t.line_of_row[i];
    const double ti = t.Number(i, time);
    CheckIncreasing(t, i, ti, previous);
    previous = ti;
    if (i == 0) log.first_time_s = ti;
    log.last_time_s = ti;
    const std::string& st = t.rows[i][status];
    if (st == "lost") {
      ++log.lost_rows;
      continue;
    }
    if (st != "ok" && st != "degraded")
      Throw(path.string(), " line ", line, ", column 'status': expected ok, degraded or lost, found '", st, "'");
    TrackerSample s;
    s.line = line;
    s.time_s = ti;
    const double f = t.Number(i, frame);
    if (f != std::floor(f) || f < 0 || f > 2e9)
      Throw(path.string(), " line ", line, ", column 'frame': expected a non-negative integer, found '",
            t.rows[i][frame], "'");
    s.frame = static_cast<int>(f);
    const Eigen::Quaterniond q(t.Number(i, qw), t.Number(i, qx), t.Number(i, qy), t.Number(i, qz));
    if (!IsUnitQuaternion(q))
      Throw(path.string(), " line ", line, ": quaternion (qw, qx, qy, qz) must have unit norm, has norm ", q.norm());
    s.T_rig_target = Pose::FromQuaternion(q.normalized(), Vec3(t.Number(i, x), t.Number(i, yc), t.Number(i, z)));
    if (const double r = s.T_rig_target.t.norm(); !(r <= kMaxRigRangeM)) {
      if (!std::isfinite(r))
        Throw(path.string(), " line ", line, ": (x_m, y_m, z_m) puts the target absurdly far from the rig (",
              t.rows[i][x], ", ", t.rows[i][yc], ", ", t.rows[i][z], "): a mistyped row? expected metres");
      Throw(path.string(), " line ", line, ": (x_m, y_m, z_m) puts the target ", r,
            " m from the rig, farther than a camera rig measures (", kMaxRigRangeM,
            " m): are the positions in mm? expected metres");
    }
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) s.covariance(r, c) = t.Number(i, cov[r][c]);
    const double scale = s.covariance.cwiseAbs().maxCoeff();
    for (int r = 0; r < 6; ++r)
      for (int c = r + 1; c < 6; ++c)
        if (std::abs(s.covariance(r, c) - s.covariance(c, r)) > 1e-9 * scale)
          Throw(path.string(), " line ", line, ": covariance is not symmetric (cov_", kAxes[r], "_", kAxes[c], " = ",
                s.covariance(r, c), ", cov_", kAxes[c], "_", kAxes[r], " = ", s.covariance(c, r), ")");
    s.covariance = 0.5 * (s.covariance + s.covariance.transpose()).eval();
    const Eigen::SelfAdjointEigenSolver<Mat6> es(s.covariance);
    if (!(es.eigenvalues()[0] > 1e-14 * es.eigenvalues()[5]) || s.covariance.llt().info() != Eigen::Success)
      Throw(path.string(), " line ", line, ": covariance is not positive definite (eigenvalues from ",
            es.eigenvalues()[0], " to ", es.eigenvalues()[5], "); a pose used for fusion needs one");
    log.samples.push_back(std::move(s));
  }
  if (log.samples.empty())
    Throw(path.string(), " line ", t.line_of_row.back(), ": every row has status lost, no pose to fuse");
  return log;
}

JointLog ReadJointLog(const fs::path& path, const RobotModel& robot) {
  int header_line = 0;
  const CsvTable t = ReadLog(path, "robot joint", &header_line);
  if (!t.HasColumn("time_s"))
    Throw(path.string(), " line ", header_line, ": missing column 'time_s'; expected time_s and one column per joint");
  // The joints' columns as every robot log names them (model/robot_measurements.h).
  std::set<int> used{t.Column("time_s")};
  const JointColumns jc = FindJointColumns(t, robot, &used);
  for (size_t c = 0; c < t.header.size(); ++c)
    if (!used.count(static_cast<int>(c)))
      Throw(path.string(), " line ", header_line, ": column '", t.header[c], "' is not time_s or a joint of robot '",
            robot.Name(), "' (", robot.NumActuated(), " joints); remove it or give the robot the log was made with");
  const int time = t.Column("time_s");
  const int n = robot.NumActuated();
  JointLog log;
  log.source = path;
  double previous = 0.0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    JointSample s;
    s.line = t.line_of_row[i];
    s.time_s = t.Number(i, time);
    CheckIncreasing(t, i, s.time_s, previous);
    previous = s.time_s;
    Eigen::VectorXd qa(n);
    for (int j = 0; j < n; ++j) qa[j] = t.Number(i, jc.column[j]) * jc.scale[j];
    s.q = robot.ChainValues(qa);
    std::string why;
    if (!robot.WithinLimits(s.q, &why)) Throw(path.string(), " line ", s.line, ": ", why);
    log.samples.push_back(std::move(s));
  }
  return log;
}

InclinometerLog ReadInclinometerLog(const fs::path& path) {
  int header_line = 0;
  const CsvTable t = ReadLog(path, "inclinometer", &header_line);
  const int time = t.Column("time_s");
  const auto cx = UnitColumn(t, header_line, "tilt_x", kAngle);
  const auto cy = UnitColumn(t, header_line, "tilt_y", kAngle);
  InclinometerLog log;
  log.source = path;
  double previous = 0.0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    InclinometerSample s;
    s.line = t.line_of_row[i];
    s.time_s = t.Number(i, time);
    CheckIncreasing(t, i, s.time_s, previous);
    previous = s.time_s;
    s.reading = Vec2(t.Number(i, cx.first) * cx.second, t.Number(i, cy.first) * cy.second);
    if (std::abs(s.reading.x()) >= 0.5 * std::numbers::pi || std::abs(s.reading.y()) >= 0.5 * std::numbers::pi)
      Throw(path.string(), " line ", s.line, ": a tilt reading must lie within +-90 deg");
    log.samples.push_back(std::move(s));
  }
  return log;
}

FusionSetup ParseFusionSetup(const std::string& yaml_text, const fs::path& source, const fs::path& base_dir) {
  const std::string name = "setup file " + source.string();
  const Yaml y(name);
  YAML::Node root;
  try {
    root = LoadYaml(yaml_text, name);
  } catch (const YAML::Exception& e) {
    Throw(name, ": not valid YAML: ", e.what());
  }
  if (!root || root.IsNull()) Throw(name, " line 1: empty file, expected the setup keys T_base_rig and T_flange_target");
  try {
    return ParseRoot(root, y, source, base_dir);
  } catch (const YAML::Exception& e) {
    Throw(name, ": ", e.what());
  }
}

FusionSetup ReadFusionSetup(const fs::path& path) {
  return ParseFusionSetup(ReadTextFile(path), path, path.parent_path());
}

}  // namespace mcms
