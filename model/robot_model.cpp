#include "model/robot_model.h"

#include <numbers>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include <Eigen/Eigenvalues>

#include "core/limits.h"
#include "core/error.h"
#include "core/io.h"
#include "core/yaml.h"
#include "model/joint.h"

namespace mcms {

namespace internal {
// Text of model/robots/kuka_kr5_arc.yaml, generated into the build tree by
// calib/CMakeLists.txt from calib/default_robot.cpp.in.
extern const char* const kDefaultRobotYaml;
extern const char* const kDefaultRobotSource;
}  // namespace internal

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

const char* TypeName(JointType t) { return t == JointType::kRevolute ? "revolute" : "prismatic"; }

// "joint A2 (2 of 6)"
std::string JointLabel(const std::vector<Joint>& joints, int i) {
  std::ostringstream s;
  s << "joint " << (joints[i].name.empty() ? std::to_string(i + 1) : joints[i].name) << " (" << i + 1 << " of "
    << joints.size() << ")";
  return s.str();
}

// A joint value or limit for messages: degrees for revolute joints, metres otherwise.
std::string JointValueText(const Joint& j, double v) {
  std::ostringstream s;
  s.precision(3);
  if (j.type == JointType::kRevolute)
    s << std::fixed << v / kDeg << " deg";
  else
    s << std::fixed << v << " m";
  return s.str();
}

// ---- YAML reading: every error names the source, the line and the field. ----
class YamlReader {
 public:
  explicit YamlReader(std::string source) : source_(std::move(source)) {}

  template <typename... Parts>
  [[noreturn]] void Fail(const YAML::Node& at, const Parts&... parts) const {
    if (at.IsDefined() && at.Mark().line >= 0)
      Throw(source_, " line ", at.Mark().line + 1, ": ", parts...);
    Throw(source_, ": ", parts...);
  }

  void CheckKeys(const YAML::Node& map, const std::set<std::string>& allowed, const std::string& where) const {
    if (!map.IsMap()) Fail(map, where, " must be a map of key: value");
    for (const auto& kv : map) {
      const std::string key = kv.first.as<std::string>();
      if (!allowed.count(key)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        Fail(kv.first, where, ": unknown key '", key, "' (expected one of: ", list, ")");
      }
    }
  }

  // allow_infinite: YAML's .inf / -.inf are accepted (open joint limits).
  double Number(const YAML::Node& n, const std::string& what, bool allow_infinite = false) const {
    double v = 0.0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      Fail(n, what, " must be a number");
    }
    if (std::isnan(v) || (!allow_infinite && !std::isfinite(v))) Fail(n, what, " must be finite");
    return v;
  }

  std::vector<double> Numbers(const YAML::Node& n, size_t count, const std::string& what,
                              bool allow_infinite = false) const {
    if (!n.IsSequence() || n.size() != count) Fail(n, what, " must be a list of ", count, " numbers");
    std::vector<double> v;
    for (size_t i = 0; i < count; ++i) v.push_back(Number(n[i], what, allow_infinite));
    return v;
  }

  // A quantity that may be given in one of several units: key_<suffix> for each suffix,
  // at most one present; the value is multiplied by the suffix's scale to SI.
  // Returns nullopt when none is present.
  std::optional<YAML::Node> OneOf(const YAML::Node& map, const std::string& key,
                                  const std::vector<std::pair<std::string, double>>& units, double* scale,
                                  const std::string& where) const {
    std::optional<YAML::Node> found;
    std::string found_key;
    for (const auto& [suffix, s] : units) {
      const std::string k = key + "_" + suffix;
      if (map[k]) {
        if (found) Fail(map[k], where, ": give only one of '", found_key, "' and '", k, "'");
        found = map[k];
        found_key = k;
        *scale = s;
      }
    }
    return found;
  }

  const std::string& Source() const { return source_; }

 private:
  std::string source_;
};

const std::vector<std::pair<std::string, double>> kAngleUnits = {{"rad", 1.0}, {"deg", kDeg}};
const std::vector<std::pair<std::string, double>> kLengthUnits = {{"m", 1.0}};

RobotModel ParseRoot(const YAML::Node& root, const YamlReader& in) {
  in.CheckKeys(root,
               {"name", "convention", "encoder_sigma_rad", "encoder_sigma_deg", "encoder_sigma_m", "tool", "joints"},
               "robot description");
  std::string name;
  if (root["name"]) name = root["name"].as<std::string>();

  if (!root["convention"]) in.Fail(root, "missing key 'convention' (standard_dh, modified_dh or urdf)");
  const std::string conv = root["convention"].as<std::string>();
  ChainConvention convention;
  if (conv == "standard_dh")
    convention = ChainConvention::kStandard;
  else if (conv == "modified_dh")
    convention = ChainConvention::kModified;
  else if (conv == "urdf")
    convention = ChainConvention::kUrdf;
  else
    in.Fail(root["convention"], "convention '", conv, "' is not standard_dh, modified_dh or urdf");
  const bool urdf = convention == ChainConvention::kUrdf;

  double scale = 1.0;
  double sigma_revolute = 0.0, sigma_prismatic = 0.0;
  if (auto n = in.OneOf(root, "encoder_sigma", kAngleUnits, &scale, "robot")) {
    sigma_revolute = in.Number(*n, "encoder_sigma") * scale;
    if (sigma_revolute < 0) in.Fail(*n, "encoder_sigma must be >= 0");
  }
  if (root["encoder_sigma_m"]) {
    sigma_prismatic = in.Number(root["encoder_sigma_m"], "encoder_sigma_m");
    if (sigma_prismatic < 0) in.Fail(root["encoder_sigma_m"], "encoder_sigma_m must be >= 0");
  }

  Pose tool;
  ToolMass tool_mass;
  if (const YAML::Node t = root["tool"]) {
    in.CheckKeys(t, {"translation_m", "quaternion_wxyz", "mass_kg", "com_m"}, "tool");
    if (t["translation_m"]) {
      const auto v = in.Numbers(t["translation_m"], 3, "tool translation_m");
      tool.t = Vec3(v[0], v[1], v[2]);
    }
    if (t["quaternion_wxyz"]) {
      const auto v = in.Numbers(t["quaternion_wxyz"], 4, "tool quaternion_wxyz");
      const Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
      if (!IsUnitQuaternion(q))
        in.Fail(t["quaternion_wxyz"], "tool quaternion_wxyz must have unit norm, has ", q.norm());
      tool.R = q.normalized().toRotationMatrix();
    }
    if (t["com_m"] && !t["mass_kg"]) in.Fail(t["com_m"], "tool: com_m needs mass_kg");
    if (t["mass_kg"]) {
      tool_mass.mass_kg = in.Number(t["mass_kg"], "tool mass_kg");
      if (tool_mass.mass_kg < 0) in.Fail(t["mass_kg"], "tool mass_kg must be >= 0, got ", tool_mass.mass_kg);
      if (t["com_m"]) {
        const auto v = in.Numbers(t["com_m"], 3, "tool com_m");
        tool_mass.com_m = Vec3(v[0], v[1], v[2]);
      }
    }
  }

  const YAML::Node list = root["joints"];
  if (!list || !list.IsSequence() || list.size() == 0) in.Fail(root, "missing or empty list 'joints'");
  std::vector<Joint> joints;
  for (size_t i = 0; i < list.size(); ++i) {
    const YAML::Node jn = list[i];
    const std::string where = "joint " + std::to_string(i + 1);
    if (urdf)
      in.CheckKeys(jn,
                   {"name", "type", "origin_xyz_m", "origin_rpy_rad", "axis", "limits_rad", "limits_deg", "limits_m",
                    "encoder_sigma_rad", "encoder_sigma_deg", "encoder_sigma_m", "error_motion", "mass_kg", "com_m",
                    "mimic"},
                   where);
    else
      in.CheckKeys(jn,
                   {"name", "type", "a_m", "d_m", "alpha_rad", "alpha_deg", "theta_offset_rad", "theta_offset_deg",
                    "limits_rad", "limits_deg", "limits_m", "encoder_sigma_rad", "encoder_sigma_deg",
                    "encoder_sigma_m", "error_motion", "mass_kg", "com_m", "mimic"},
                   where);
    Joint j;
    if (jn["name"]) j.name = jn["name"].as<std::string>();
    const std::string label = j.name.empty() ? where : where + " (" + j.name + ")";
    if (jn["type"]) {
      const std::string type = jn["type"].as<std::string>();
      if (type == "revolute")
        j.type = JointType::kRevolute;
      else if (type == "prismatic")
        j.type = JointType::kPrismatic;
      else
        in.Fail(jn["type"], label, ": type '", type, "' is not revolute or prismatic");
    }
    const bool revolute = j.type == JointType::kRevolute;
    if (urdf) {
      // origin_xyz_m, origin_rpy_rad (URDF's fixed-axis roll, pitch, yaw) and axis.
      for (const char* key : {"origin_xyz_m", "origin_rpy_rad", "axis"})
        if (!jn[key]) in.Fail(jn, label, ": missing key '", key, "'");
      const auto xyz = in.Numbers(jn["origin_xyz_m"], 3, label + " origin_xyz_m");
      const auto rpy = in.Numbers(jn["origin_rpy_rad"], 3, label + " origin_rpy_rad");
      const auto ax = in.Numbers(jn["axis"], 3, label + " axis");
      j.origin = Pose{RotationOfRpy(Vec3(rpy[0], rpy[1], rpy[2])), Vec3(xyz[0], xyz[1], xyz[2])};
      const Vec3 axis(ax[0], ax[1], ax[2]);
      if (!(axis.norm() > 1e-9)) in.Fail(jn["axis"], label, ": axis must not be zero");
      j.axis = axis.normalized();
    } else {
      for (const char* key : {"a_m", "d_m"})
        if (!jn[key]) in.Fail(jn, label, ": missing key '", key, "'");
      j.a = in.Number(jn["a_m"], label + " a_m");
      j.d = in.Number(jn["d_m"], label + " d_m");
      // A DH angle beyond a turn under a radian key is degrees (90 for pi/2).
      const auto angle = [&](const char* key) {
        double v = 0.0;
        if (auto n = in.OneOf(jn, key, kAngleUnits, &scale, label)) {
          v = in.Number(*n, label + " " + key) * scale;
          if (scale == 1.0 && std::abs(v) > 2 * std::numbers::pi + 1e-9)
            in.Fail(*n, label, " ", key, "_rad is ", v, ", more than a turn: degrees? give ", key, "_deg");
        } else {
          in.Fail(jn, label, ": missing key '", key, "_rad' (or '", key, "_deg')");
        }
        return v;
      };
      j.alpha = angle("alpha");
      j.theta_offset = angle("theta_offset");
    }

    const auto& value_units = revolute ? kAngleUnits : kLengthUnits;
    const char* wrong_unit = revolute ? "m" : "rad";
    for (const std::string& k : {std::string("limits_"), std::string("encoder_sigma_")})
      if (jn[k + wrong_unit] || (!revolute && jn[k + "deg"]))
        in.Fail(jn, label, ": a ", TypeName(j.type), " joint takes ", k, revolute ? "rad/deg" : "m");
    if (auto n = in.OneOf(jn, "limits", value_units, &scale, label)) {
      const auto v = in.Numbers(*n, 2, label + " limits", /*allow_infinite=*/true);
      j.lower = v[0] * scale;
      j.upper = v[1] * scale;
      if (!(j.lower < j.upper)) in.Fail(*n, label, ": limits must be [lower, upper] with lower < upper");
    }
    j.encoder_sigma = revolute ? sigma_revolute : sigma_prismatic;
    if (auto n = in.OneOf(jn, "encoder_sigma", value_units, &scale, label)) {
      j.encoder_sigma = in.Number(*n, label + " encoder_sigma") * scale;
      if (j.encoder_sigma < 0) in.Fail(*n, label, ": encoder_sigma must be >= 0");
    }
    if (const YAML::Node em = jn["error_motion"]) {
      // error_motion: a list, harmonic 1, 2, ... in order, each
      //   {sin: [rx_rad, ry_rad, rz_rad, x_m, y_m, z_m], cos: [...]}
      if (!revolute) in.Fail(em, label, ": error_motion is for revolute joints only");
      if (!em.IsSequence()) in.Fail(em, label, ": error_motion must be a list of {sin: [6], cos: [6]}, one per harmonic");
      for (size_t h = 0; h < em.size(); ++h) {
        const std::string w = label + " error_motion harmonic " + std::to_string(h + 1);
        in.CheckKeys(em[h], {"sin", "cos"}, w);
        for (const char* k : {"sin", "cos"})
          if (!em[h][k]) in.Fail(em[h], w, ": missing key '", k, "' ([rx_rad, ry_rad, rz_rad, x_m, y_m, z_m])");
        const auto vs = in.Numbers(em[h]["sin"], 6, w + " sin"), vc = in.Numbers(em[h]["cos"], 6, w + " cos");
        j.error_motion_sin.push_back(Eigen::Map<const Vec6>(vs.data()));
        j.error_motion_cos.push_back(Eigen::Map<const Vec6>(vc.data()));
      }
    }
    if (jn["com_m"] && !jn["mass_kg"]) in.Fail(jn["com_m"], label, ": com_m needs mass_kg");
    if (jn["mass_kg"]) {
      // The link's mass and centre of mass (in this joint's DH frame i): the arm's own
      // weight, which deflects compliant joints.
      j.mass_kg = in.Number(jn["mass_kg"], label + " mass_kg");
      if (*j.mass_kg < 0) in.Fail(jn["mass_kg"], label, ": mass_kg must be >= 0 (a mass), got ", *j.mass_kg);
      if (jn["com_m"]) {
        const auto v = in.Numbers(jn["com_m"], 3, label + " com_m");
        j.com_m = Vec3(v[0], v[1], v[2]);
      }
    }
    if (const YAML::Node mn = jn["mimic"]) {
      // mimic: {joint: name, multiplier: m, offset: o}: q = m * q_joint + o (a URDF <mimic>).
      in.CheckKeys(mn, {"joint", "multiplier", "offset"}, label + " mimic");
      if (!mn["joint"]) in.Fail(mn, label, ": mimic needs 'joint' (the driving joint's name)");
      j.mimics = mn["joint"].as<std::string>();
      if (mn["multiplier"]) j.mimic_multiplier = in.Number(mn["multiplier"], label + " mimic multiplier");
      if (mn["offset"]) j.mimic_offset = in.Number(mn["offset"], label + " mimic offset");
    }
    joints.push_back(j);
  }
  int with_mass = 0;
  for (const Joint& j : joints) with_mass += j.mass_kg.has_value();
  if (with_mass > 0 && with_mass < static_cast<int>(joints.size()))
    in.Fail(list, "mass_kg is given for ", with_mass, " of ", joints.size(),
            " joints; give every link's mass (0 for a massless one) or none");
  RobotModel model(name, convention, joints, tool);
  model.SetToolMass(tool_mass);
  return model;
}

}  // namespace

RobotModel::RobotModel(std::string name, ChainConvention convention, std::vector<Joint> joints,
                       const Pose& T_flange_tool)
    : name_(std::move(name)), convention_(convention), joints_(std::move(joints)), T_flange_tool_(T_flange_tool) {
  const std::string who = "robot '" + name_ + "'";
  if (joints_.empty()) Throw(who, ": needs at least one joint");
  if (NumJoints() > kMaxRobotJoints)
    Throw(who, ": ", NumJoints(), " joints; a robot's chain has at most ", kMaxRobotJoints, " (core/limits.h)");
  for (int i = 0; i < NumJoints(); ++i) {
    const Joint& j = joints_[i];
    for (double v : {j.a, j.alpha, j.d, j.theta_offset})
      if (!std::isfinite(v)) Throw(who, ": ", JointLabel(joints_, i), " has a non-finite DH parameter");
    if (!j.origin.R.allFinite() || !j.origin.t.allFinite() ||
        (j.origin.R.transpose() * j.origin.R - Mat3::Identity()).norm() > 1e-9 || j.origin.R.determinant() < 0)
      Throw(who, ": ", JointLabel(joints_, i), " origin must be a finite rigid transform");
    if (!j.axis.allFinite() || std::abs(j.axis.norm() - 1.0) > 1e-9)
      Throw(who, ": ", JointLabel(joints_, i), " axis must be a unit vector");
    if (std::isnan(j.lower) || std::isnan(j.upper) || !(j.lower < j.upper))
      Throw(who, ": ", JointLabel(joints_, i), " needs limits lower < upper");
    if (!(j.encoder_sigma >= 0) || !std::isfinite(j.encoder_sigma))
      Throw(who, ": ", JointLabel(joints_, i), " needs a finite encoder sigma >= 0");
    if (j.error_motion_sin.size() != j.error_motion_cos.size())
      Throw(who, ": ", JointLabel(joints_, i), " has ", j.error_motion_sin.size(), " sine and ",
            j.error_motion_cos.size(), " cosine error-motion harmonics; give both for each harmonic");
    if (j.Harmonics() > 0 && j.type != JointType::kRevolute)
      Throw(who, ": ", JointLabel(joints_, i), " is prismatic; error motion is for revolute joints only");
    for (int h = 0; h < j.Harmonics(); ++h)
      if (!j.error_motion_sin[h].allFinite() || !j.error_motion_cos[h].allFinite())
        Throw(who, ": ", JointLabel(joints_, i), " error motion harmonic ", h + 1, " is not finite");
    if (j.mass_kg && !(std::isfinite(*j.mass_kg) && *j.mass_kg >= 0))
      Throw(who, ": ", JointLabel(joints_, i), " mass_kg is ", *j.mass_kg, "; expected a finite mass >= 0");
    if (!j.com_m.allFinite()) Throw(who, ": ", JointLabel(joints_, i), " com_m is not finite");
    // Limits (core/limits.h): no robot is larger, no encoder noisier, no link heavier.
    const std::string at = who + ": " + JointLabel(joints_, i);
    CheckMagnitude(j.a, kMaxRobotLengthM, at + " a", "m");
    CheckMagnitude(j.d, kMaxRobotLengthM, at + " d", "m");
    CheckMagnitude(j.origin.t.lpNorm<Eigen::Infinity>(), kMaxRobotLengthM, at + " origin (largest coordinate)", "m");
    CheckMagnitude(j.com_m.lpNorm<Eigen::Infinity>(), kMaxRobotLengthM, at + " com_m (largest coordinate)", "m");
    CheckMagnitude(j.encoder_sigma, kMaxEncoderSigma, at + " encoder_sigma",
                   j.type == JointType::kRevolute ? "rad" : "m");
    if (j.mass_kg) CheckMagnitude(*j.mass_kg, kMaxMassKg, at + " mass_kg", "kg");
  }
  {
    // The whole chain stretched out: no robot reaches farther than a rig measures.
    double reach = T_flange_tool_.t.norm();
    for (const Joint& j : joints_) reach += std::abs(j.a) + std::abs(j.d) + j.origin.t.norm();
    if (reach > kMaxRigRangeM)
      Throw(who, ": its link lengths add up to ", reach, " m, more than any robot reaches (", kMaxRigRangeM,
            " m): millimetres read as metres? expected metres");
  }
  for (int i = 0; i < NumJoints(); ++i)
    for (int k = 0; k < i; ++k)
      if (!joints_[i].name.empty() && joints_[i].name == joints_[k].name)
        Throw(who, ": joints ", k + 1, " and ", i + 1, " are both named '", joints_[i].name,
              "'; a log names its joint columns by them, so each name must be unique");
  int with_mass = 0;
  for (const Joint& j : joints_) with_mass += j.mass_kg.has_value();
  if (with_mass > 0 && with_mass < NumJoints())
    Throw(who, ": mass_kg is given for ", with_mass, " of ", NumJoints(),
          " joints; give every link's mass (0 for a massless one) or none");
  if (!T_flange_tool_.R.allFinite() || !T_flange_tool_.t.allFinite() ||
      (T_flange_tool_.R.transpose() * T_flange_tool_.R - Mat3::Identity()).norm() > 1e-9 ||
      T_flange_tool_.R.determinant() < 0)
    Throw(who, ": T_flange_tool must be a finite rigid transform");
  CheckMagnitude(T_flange_tool_.t.lpNorm<Eigen::Infinity>(), kMaxRobotLengthM, who + ": the tool (largest coordinate)",
                 "m");
  // The actuated joints: the chain's own, and the drivers of mimic joints.
  actuated_of_.assign(NumJoints(), -1);
  const auto Find = [&](const std::string& name) {
    for (size_t a = 0; a < actuated_.size(); ++a)
      if (actuated_[a].name == name) return static_cast<int>(a);
    return -1;
  };
  for (int i = 0; i < NumJoints(); ++i) {
    const Joint& j = joints_[i];
    if (j.mimics.empty()) {
      actuated_of_[i] = static_cast<int>(actuated_.size());
      actuated_.push_back({j.name, j.type, j.lower, j.upper});
      continue;
    }
    mimic_ = true;
    if (!(std::isfinite(j.mimic_multiplier) && j.mimic_multiplier != 0.0) || !std::isfinite(j.mimic_offset))
      Throw(who, ": ", JointLabel(joints_, i), " mimics '", j.mimics, "' with multiplier ", j.mimic_multiplier,
            " and offset ", j.mimic_offset, "; expected a finite non-zero multiplier and a finite offset");
    if (j.mimics == j.name) Throw(who, ": ", JointLabel(joints_, i), " mimics itself");
    for (int k = 0; k < NumJoints(); ++k)
      if (joints_[k].name == j.mimics && !joints_[k].mimics.empty())
        Throw(who, ": ", JointLabel(joints_, i), " mimics '", j.mimics, "', which mimics '", joints_[k].mimics,
              "' itself; a mimic joint follows an actuated joint");
  }
  for (int i = 0; i < NumJoints(); ++i) {
    const Joint& j = joints_[i];
    if (j.mimics.empty()) continue;
    int a = Find(j.mimics);
    // The driver's range from this mimic joint's limits.
    double lo = (j.lower - j.mimic_offset) / j.mimic_multiplier, hi = (j.upper - j.mimic_offset) / j.mimic_multiplier;
    if (lo > hi) std::swap(lo, hi);
    if (a < 0) {
      // A driver outside the chain: recorded where its first mimic joint is.
      int at = 0;
      for (int k = 0; k < i; ++k) at = std::max(at, actuated_of_[k] + 1);
      actuated_.insert(actuated_.begin() + at, ActuatedJoint{j.mimics, j.type, lo, hi});
      for (int k = 0; k < NumJoints(); ++k)
        if (actuated_of_[k] >= at) ++actuated_of_[k];
      a = at;
    } else if (!(std::isnan(lo) || std::isnan(hi))) {
      ActuatedJoint& d = actuated_[a];
      d.lower = std::max(d.lower, lo);
      d.upper = std::min(d.upper, hi);
      if (!(d.lower < d.upper))
        Throw(who, ": the limits of the joints that mimic '", j.mimics, "' leave it no range");
    }
    actuated_of_[i] = a;
  }
}

Eigen::VectorXd RobotModel::ChainValues(const Eigen::VectorXd& qa) const {
  if (qa.size() != NumActuated())
    Throw("robot '", name_, "': ", qa.size(), " actuated joint values, expected ", NumActuated());
  if (!mimic_) return qa;
  Eigen::VectorXd q(NumJoints());
  for (int i = 0; i < NumJoints(); ++i) {
    const Joint& j = joints_[i];
    const double v = qa[actuated_of_[i]];
    q[i] = j.mimics.empty() ? v : j.mimic_multiplier * v + j.mimic_offset;
  }
  return q;
}

Eigen::VectorXd RobotModel::ActuatedValues(const Eigen::VectorXd& q) const {
  if (q.size() != NumJoints()) Throw("robot '", name_, "': ", q.size(), " joint values, expected ", NumJoints());
  if (!mimic_) return q;
  Eigen::VectorXd qa = Eigen::VectorXd::Constant(NumActuated(), std::nan(""));
  for (int i = 0; i < NumJoints(); ++i) {
    const Joint& j = joints_[i];
    double& v = qa[actuated_of_[i]];
    if (!std::isnan(v)) continue;
    v = j.mimics.empty() ? q[i] : (q[i] - j.mimic_offset) / j.mimic_multiplier;
  }
  return qa;
}

bool RobotModel::HasMasses() const {
  for (const Joint& j : joints_)
    if (!j.mass_kg) return false;
  return true;
}

RobotModel RobotModel::WithJoints(std::vector<Joint> joints) const {
  RobotModel m(name_, convention_, std::move(joints), T_flange_tool_);
  m.tool_mass_ = tool_mass_;
  m.urdf_ = urdf_;
  return m;
}

void RobotModel::SetToolMass(const ToolMass& m) {
  if (!(std::isfinite(m.mass_kg) && m.mass_kg >= 0) || !m.com_m.allFinite())
    Throw("robot '", name_, "': tool mass_kg ", m.mass_kg, " and com_m must be finite, with a mass >= 0");
  tool_mass_ = m;
}

RobotModel RobotModel::Default() {
  static const RobotModel model = Parse(internal::kDefaultRobotYaml, internal::kDefaultRobotSource);
  return model;
}

// RobotModel::Read is in model/urdf.cpp: it reads a URDF or this YAML.

RobotModel RobotModel::Parse(const std::string& yaml_text, const std::string& source) {
  const YamlReader in(source);
  YAML::Node root;
  try {
    root = LoadYaml(yaml_text, source);
  } catch (const YAML::Exception& e) {
    Throw(source, ": not valid YAML: ", e.what());
  }
  try {
    return ParseRoot(root, in);
  } catch (const YAML::Exception& e) {
    Throw(source, ": ", e.what());
  } catch (const InputError& e) {
    // Constructor errors do not know the source; name it once.
    const std::string what = e.what();
    if (what.rfind(source, 0) == 0) throw;
    Throw(source, ": ", what);
  }
}

std::string RobotModel::ToYaml() const {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap;
  out << YAML::Key << "name" << YAML::Value << name_;
  out << YAML::Key << "convention" << YAML::Value
      << (convention_ == ChainConvention::kStandard   ? "standard_dh"
          : convention_ == ChainConvention::kModified ? "modified_dh"
                                                      : "urdf");
  if (T_flange_tool_.R != Mat3::Identity() || T_flange_tool_.t != Vec3::Zero() || tool_mass_.mass_kg > 0) {
    // The quaternion is written from the rotation matrix; reading it back reproduces
    // the matrix to rounding (1e-16), not bit for bit.
    const Eigen::Quaterniond q = T_flange_tool_.Quaternion();
    out << YAML::Key << "tool" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "translation_m" << YAML::Value << YAML::Flow
        << std::vector<double>{T_flange_tool_.t.x(), T_flange_tool_.t.y(), T_flange_tool_.t.z()};
    out << YAML::Key << "quaternion_wxyz" << YAML::Value << YAML::Flow
        << std::vector<double>{q.w(), q.x(), q.y(), q.z()};
    if (tool_mass_.mass_kg > 0) {
      out << YAML::Key << "mass_kg" << YAML::Value << tool_mass_.mass_kg;
      out << YAML::Key << "com_m" << YAML::Value << YAML::Flow
          << std::vector<double>{tool_mass_.com_m.x(), tool_mass_.com_m.y(), tool_mass_.com_m.z()};
    }
    out << YAML::EndMap;
  }
  out << YAML::Key << "joints" << YAML::Value << YAML::BeginSeq;
  for (const Joint& j : joints_) {
    const bool rev = j.type == JointType::kRevolute;
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << j.name;
    out << YAML::Key << "type" << YAML::Value << TypeName(j.type);
    if (convention_ == ChainConvention::kUrdf) {
      // The joint's zero offset folded into its origin (the URDF form has none).
      Pose motion;
      if (rev)
        motion.R = Eigen::AngleAxisd(j.theta_offset, j.axis).toRotationMatrix();
      else
        motion.t = j.d * j.axis;
      const Pose o = j.origin * motion;
      const Vec3 rpy = RpyOf(o.R);
      out << YAML::Key << "origin_xyz_m" << YAML::Value << YAML::Flow << std::vector<double>{o.t.x(), o.t.y(), o.t.z()};
      out << YAML::Key << "origin_rpy_rad" << YAML::Value << YAML::Flow << std::vector<double>{rpy.x(), rpy.y(), rpy.z()};
      out << YAML::Key << "axis" << YAML::Value << YAML::Flow
          << std::vector<double>{j.axis.x(), j.axis.y(), j.axis.z()};
    } else {
      out << YAML::Key << "d_m" << YAML::Value << j.d;
      out << YAML::Key << "a_m" << YAML::Value << j.a;
      out << YAML::Key << "alpha_rad" << YAML::Value << j.alpha;
      out << YAML::Key << "theta_offset_rad" << YAML::Value << j.theta_offset;
    }
    if (std::isfinite(j.lower) || std::isfinite(j.upper)) {
      // An open side is written as YAML's .inf / -.inf.
      out << YAML::Key << (rev ? "limits_rad" : "limits_m") << YAML::Value << YAML::Flow
          << std::vector<double>{j.lower, j.upper};
    }
    out << YAML::Key << (rev ? "encoder_sigma_rad" : "encoder_sigma_m") << YAML::Value << j.encoder_sigma;
    if (j.mass_kg) {
      out << YAML::Key << "mass_kg" << YAML::Value << *j.mass_kg;
      out << YAML::Key << "com_m" << YAML::Value << YAML::Flow
          << std::vector<double>{j.com_m.x(), j.com_m.y(), j.com_m.z()};
    }
    if (!j.mimics.empty()) {
      out << YAML::Key << "mimic" << YAML::Value << YAML::Flow << YAML::BeginMap;
      out << YAML::Key << "joint" << YAML::Value << j.mimics;
      out << YAML::Key << "multiplier" << YAML::Value << j.mimic_multiplier;
      out << YAML::Key << "offset" << YAML::Value << j.mimic_offset;
      out << YAML::EndMap;
    }
    if (j.Harmonics() > 0) {
      out << YAML::Key << "error_motion" << YAML::Value << YAML::Flow << YAML::BeginSeq;
      for (int h = 0; h < j.Harmonics(); ++h) {
        const Vec6 &vs = j.error_motion_sin[h], &vc = j.error_motion_cos[h];
        out << YAML::Flow << YAML::BeginMap;
        out << YAML::Key << "sin" << YAML::Value << YAML::Flow << std::vector<double>(vs.data(), vs.data() + 6);
        out << YAML::Key << "cos" << YAML::Value << YAML::Flow << std::vector<double>(vc.data(), vc.data() + 6);
        out << YAML::EndMap;
      }
      out << YAML::EndSeq;
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

void RobotModel::Write(const std::filesystem::path& path) const {
  const std::string text = ToYaml();
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

bool RobotModel::WithinLimits(const Eigen::VectorXd& q, std::string* why, double slack_share) const {
  std::ostringstream s;
  if (q.size() != NumJoints()) {
    s << "robot '" << name_ << "' has " << NumJoints() << " joints, got " << q.size() << " joint values";
  } else {
    for (int i = 0; i < NumJoints(); ++i) {
      const Joint& j = joints_[i];
      if (!std::isfinite(q[i])) {
        s << "robot '" << name_ << "': " << JointLabel(joints_, i) << " value is not finite";
        break;
      }
      const double slack = std::isfinite(j.upper - j.lower) ? slack_share * (j.upper - j.lower) : 0.0;
      if (q[i] < j.lower - slack) {
        s << "robot '" << name_ << "': " << JointLabel(joints_, i) << " = " << JointValueText(j, q[i])
          << " is below its lower limit " << JointValueText(j, j.lower);
        break;
      }
      if (q[i] > j.upper + slack) {
        s << "robot '" << name_ << "': " << JointLabel(joints_, i) << " = " << JointValueText(j, q[i])
          << " is above its upper limit " << JointValueText(j, j.upper);
        break;
      }
    }
  }
  if (s.tellp() == 0) return true;
  if (why) *why = s.str();
  return false;
}

void RobotModel::CheckJoints(const Eigen::VectorXd& q) const {
  std::string why;
  if (!WithinLimits(q, &why)) Throw(why);
}

Pose RobotModel::LinkTransform(int i, double qi) const {
  const Joint& j = joints_[i];
  PoseT<double> L;
  if (j.Harmonics() == 0) {
    L = LinkTransformT<double>(convention_, j, qi, nullptr, nullptr);
  } else {
    double xi[6];
    ErrorMotionT<double>(j, qi, 0, nullptr, xi);
    L = LinkTransformT<double>(convention_, j, qi, nullptr, xi);
  }
  return Pose{L.R, L.t};
}

std::vector<Pose> RobotModel::LinkFrames(const Eigen::VectorXd& q) const {
  CheckJoints(q);
  std::vector<Pose> frames(NumJoints() + 1);
  for (int i = 0; i < NumJoints(); ++i) frames[i + 1] = frames[i] * LinkTransform(i, q[i]);
  return frames;
}

Pose RobotModel::T_base_flange(const Eigen::VectorXd& q) const {
  CheckJoints(q);
  Pose T;
  for (int i = 0; i < NumJoints(); ++i) T = T * LinkTransform(i, q[i]);
  return T;
}

Eigen::Matrix<double, 6, Eigen::Dynamic> RobotModel::Jacobian(const Eigen::VectorXd& q, EndFrame end) const {
  const std::vector<Pose> F = LinkFrames(q);
  const Vec3 p_end = end == EndFrame::kTool ? (F.back() * T_flange_tool_).t : F.back().t;
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, NumJoints());
  for (int i = 0; i < NumJoints(); ++i) {
    const JointAxis ax = AxisOf(F, i);
    if (joints_[i].type == JointType::kRevolute) {
      J.block<3, 1>(0, i) = ax.w;
      J.block<3, 1>(3, i) = ax.w.cross(p_end - ax.o);
    } else {
      J.block<3, 1>(0, i).setZero();
      J.block<3, 1>(3, i) = ax.w;
    }
  }
  return J;
}

JointAxis RobotModel::AxisOf(const std::vector<Pose>& F, int i) const {
  // Standard DH: joint i turns about z of frame i-1; modified DH: about z of frame i (its
  // origin lies on that axis, since Rz(theta) Tz(d) keep to it); URDF: about frame i's own
  // axis through its origin (origin * M(axis, q) keeps it).
  switch (convention_) {
    case ChainConvention::kStandard: return {F[i].R.col(2), F[i].t};
    case ChainConvention::kModified: return {F[i + 1].R.col(2), F[i + 1].t};
    case ChainConvention::kUrdf: return {F[i + 1].R * joints_[i].axis, F[i + 1].t};
  }
  return {};
}

Eigen::MatrixXd RobotModel::EncoderCovariance() const {
  Eigen::VectorXd s(NumJoints());
  for (int i = 0; i < NumJoints(); ++i) s[i] = joints_[i].encoder_sigma * joints_[i].encoder_sigma;
  return s.asDiagonal();
}

Mat6 RobotModel::PoseCovariance(const Eigen::VectorXd& q, const Eigen::MatrixXd& Q, EndFrame end) const {
  if (Q.rows() != NumJoints() || Q.cols() != NumJoints())
    Throw("robot '", name_, "': joint covariance must be ", NumJoints(), "x", NumJoints(), ", got ", Q.rows(), "x",
          Q.cols());
  const double scale = Q.cwiseAbs().maxCoeff();
  if (!Q.allFinite() || (Q - Q.transpose()).cwiseAbs().maxCoeff() > 1e-12 * scale)
    Throw("robot '", name_, "': joint covariance must be finite and symmetric");
  if (scale > 0) {
    const double min_eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Q, Eigen::EigenvaluesOnly).eigenvalues()[0];
    if (min_eig < -1e-12 * scale)
      Throw("robot '", name_, "': joint covariance is not positive semi-definite (eigenvalue ", min_eig, ")");
  }
  const auto J = Jacobian(q, end);
  const Mat6 C = J * Q * J.transpose();
  return 0.5 * (C + C.transpose());
}

Mat6 RobotModel::PoseCovariance(const Eigen::VectorXd& q, EndFrame end) const {
  return PoseCovariance(q, EncoderCovariance(), end);
}

std::vector<std::string> GeometryParameterNames(const RobotModel& robot) {
  static const char* const kDh[kDhParamsPerJoint] = {"theta_offset", "d", "a", "alpha"};
  static const char* const kUrdf[kUrdfParamsPerJoint] = {"offset", "x", "y", "z", "rx", "ry", "rz"};
  std::vector<std::string> names;
  for (int i = 0; i < robot.NumJoints(); ++i) {
    std::string joint = robot.Joints()[i].name;
    if (joint.empty()) {
      joint = std::to_string(i + 1);  // (GCC 12 -Wrestrict misfires on "J" + ...)
      joint.insert(joint.begin(), 'J');
    }
    for (int k = 0; k < robot.GeometryParamsPerJoint(); ++k)
      names.push_back(joint + "." + (robot.Convention() == ChainConvention::kUrdf ? kUrdf[k] : kDh[k]));
  }
  return names;
}

bool GeometryParameterIsAngle(const RobotModel& robot, int k) {
  const int s = robot.GeometryParamsPerJoint(), t = k % s;
  if (robot.Convention() != ChainConvention::kUrdf) return t == 0 || t == 3;
  if (t == 0) return robot.Joints()[k / s].type == JointType::kRevolute;
  return t >= 4;
}

double WeakGeometrySigma(const RobotModel& robot, int k) {
  return GeometryParameterIsAngle(robot, k) ? kWeakGeometryAngleRad : kWeakGeometryLengthM;
}

RobotModel WithGeometryErrors(const RobotModel& robot, const Eigen::VectorXd& delta) {
  const int s = robot.GeometryParamsPerJoint();
  if (delta.size() != robot.NumGeometryParameters())
    Throw("WithGeometryErrors: ", delta.size(), " geometric errors given, robot '", robot.Name(), "' needs ",
          robot.NumGeometryParameters());
  std::vector<Joint> joints = robot.Joints();
  for (size_t i = 0; i < joints.size(); ++i) {
    Joint& j = joints[i];
    const double* e = delta.data() + s * i;
    if (robot.Convention() == ChainConvention::kUrdf) {
      // origin G M(offset): the same transform the error model applies (model/joint.h).
      const Pose G{ExpSO3(Vec3(e[4], e[5], e[6])), Vec3(e[1], e[2], e[3])};
      Pose motion;
      if (j.type == JointType::kRevolute)
        motion.R = Eigen::AngleAxisd(e[0], j.axis).toRotationMatrix();
      else
        motion.t = e[0] * j.axis;
      j.origin = j.origin * G * motion;
    } else {
      j.theta_offset += e[0];
      j.d += e[1];
      j.a += e[2];
      j.alpha += e[3];
    }
  }
  return robot.WithJoints(joints);
}

Eigen::VectorXd UniformGrowth(const RobotModel& robot) {
  const int s = robot.GeometryParamsPerJoint();
  Eigen::VectorXd g = Eigen::VectorXd::Zero(robot.NumGeometryParameters());
  for (int i = 0; i < robot.NumJoints(); ++i) {
    const Joint& j = robot.Joints()[i];
    if (robot.Convention() == ChainConvention::kUrdf) {
      // The origin's translation (parent frame) grows: in the joint frame R^T t.
      g.segment<3>(s * i + 1) = j.origin.R.transpose() * j.origin.t;
    } else {
      g[s * i + 1] = j.d;
      g[s * i + 2] = j.a;
    }
  }
  return g;
}

}  // namespace mcms
