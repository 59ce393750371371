#include "synthetic/scenario.h"

#include <numbers>
#include <yaml-cpp/yaml.h>

#include <charconv>
#include <cmath>
#include <initializer_list>
#include <set>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/yaml.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {

// The paper's set-up (Liu, Zhang, Qu 2015): four cameras above a 1 x 0.8 x 1 m working
// volume, the five-ball target moving through it. With f = 900 px the volume's eight
// corners project between u = 273..1006 and v = 139..855 in every camera (checked in
// tests/test_synthetic_render.cpp), the cameras 1.3 to 2.8 m from its points.
const char* const kDefaultScenario = R"(# mcms synthetic scenario: the default, after the paper's set-up.
# Rig frame: z up, origin at the centre of the bottom face of the 1 x 0.8 x 1 m
# working volume (x in [-0.5, 0.5], y in [-0.4, 0.4], z in [0, 1]). Lengths in metres.
seed: 1

# Four cameras above the volume, all looking at its centre, sharing one lens:
# 1280 x 1024, OpenCV 8-parameter model with mild barrel distortion.
rig:
  type: look_at
  lensmodel: LENSMODEL_OPENCV8
  # fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
  intrinsics: [900, 900, 639.5, 511.5, -0.1, 0.03, 0.0002, -0.0001, 0, 0, 0, 0]
  imagersize: [1280, 1024]
  look_at_m: [0, 0, 0.5]
  up: [0, 0, 1]
  positions_m: [[0.8, 0.7, 2.2], [-0.8, 0.7, 2.2], [-0.8, -0.7, 2.2], [0.8, -0.7, 2.2]]
  names: [cam0, cam1, cam2, cam3]

# Target::Default(): five balls of radius 12.5 mm on a frame about 0.25 m across.
target: default

# 120 frames at 10 Hz along a Lissajous path through the volume; the orientation
# wobbles smoothly within 30 degrees of the target's own axes.
motion:
  type: lissajous
  frames: 120
  rate_hz: 10
  centre_m: [0, 0, 0.5]
  amplitude_m: [0.3, 0.2, 0.3]
  period_s: [12, 8, 9.6]
  phase_rad: [0, 0.5, 1.0]
  rotation_amplitude_deg: 30
  rotation_period_s: [7, 11, 13]
  rotation_phase_rad: [0.3, 1.1, 2.0]

# Image formation (synthetic/renderer.h). Levels in DN of the stored image.
render:
  bit_depth: 8
  exposure: 1.0
  ball_dn: 200                   # retro-reflective balls: uniformly bright discs
  background_dn: 12
  background_gradient_dn: [4, 3] # left-to-right and top-to-bottom change
  blur_sigma_px: 0.6
  gain_e_per_dn: 4               # photon noise; 0 = none
  read_noise_dn: 1.5
  supersampling: 16              # N x N sub-samples in boundary pixels
  spurious_per_image: 0          # expected spurious reflections per image
  spurious_radius_px: [1, 4]
  spurious_dn: 150
  occlusion_probability: 0       # per ball, camera and frame
  dropout_probability: 0         # per camera and frame
  noise_free: false
)";

std::string Join(const std::string& prefix, const std::string& key) { return prefix.empty() ? key : prefix + "." + key; }

// Typed access to the YAML tree; every error names the source, the line and the field.
class Reader {
 public:
  Reader(std::string source, fs::path base) : source_(std::move(source)), base_(std::move(base)) {}

  std::string Where(const YAML::Node& n) const {
    const int line = n.IsDefined() ? n.Mark().line : -1;
    return line >= 0 ? source_ + " line " + std::to_string(line + 1) : source_;
  }
  [[noreturn]] void Bad(const YAML::Node& n, const std::string& field, const std::string& what) const {
    Throw(Where(n), ": field '", field, "': ", what);
  }
  std::string Found(const YAML::Node& n) const {
    if (n.IsScalar()) return ", found '" + n.Scalar() + "'";
    if (n.IsSequence()) return ", found a list";
    if (n.IsMap()) return ", found a map";
    return ", found nothing";
  }

  void RequireMap(const YAML::Node& n, const std::string& field) const {
    if (!n.IsMap()) Bad(n, field, "expected a map of fields" + Found(n));
  }
  // Refuses keys outside `allowed`: a typo must not fall back to a default silently.
  void Keys(const YAML::Node& map, std::initializer_list<const char*> allowed, const std::string& field) const {
    RequireMap(map, field.empty() ? "(top level)" : field);
    for (const auto& kv : map) {
      const std::string key = kv.first.Scalar();
      bool ok = false;
      for (const char* a : allowed) ok = ok || key == a;
      if (!ok) {
        std::string list;
        for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        Throw(Where(kv.first), ": unknown field '", Join(field, key), "'; expected one of: ", list);
      }
    }
  }
  YAML::Node Require(const YAML::Node& map, const std::string& key, const std::string& prefix,
                     const std::string& meaning) const {
    const YAML::Node v = map[key];
    if (!v) Throw(Where(map), ": missing field '", Join(prefix, key), "' (", meaning, ")");
    return v;
  }

  double Number(const YAML::Node& n, const std::string& field) const {
    if (!n.IsScalar()) Bad(n, field, "expected a number" + Found(n));
    double v;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      Bad(n, field, "expected a number" + Found(n));
    }
    if (!std::isfinite(v)) Bad(n, field, "expected a finite number" + Found(n));
    return v;
  }
  double Positive(const YAML::Node& n, const std::string& field) const {
    const double v = Number(n, field);
    if (!(v > 0)) Bad(n, field, "expected a number > 0" + Found(n));
    return v;
  }
  // A camera's frame rate: from a time-lapse's one frame in 1000 s to a high-speed
  // camera's 1 MHz (issue 53: 1e-300 Hz rendered frame times of 63 digits).
  double Rate(const YAML::Node& n, const std::string& field) const {
    const double v = Positive(n, field);
    if (!(v >= 1e-3 && v <= 1e6)) Bad(n, field, "expected a frame rate from 0.001 to 1e6 Hz" + Found(n));
    return v;
  }
  long long Integer(const YAML::Node& n, const std::string& field, long long min) const {
    long long v = 0;
    bool ok = n.IsScalar();
    if (ok) {
      try {
        v = n.as<long long>();
      } catch (const YAML::Exception&) {
        ok = false;
      }
    }
    if (!ok || v < min) Bad(n, field, "expected an integer >= " + std::to_string(min) + Found(n));
    return v;
  }
  uint64_t Unsigned64(const YAML::Node& n, const std::string& field) const {
    const std::string s = n.IsScalar() ? n.Scalar() : "";
    uint64_t v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || ec != std::errc() || end != s.data() + s.size())
      Bad(n, field, "expected an unsigned 64-bit integer" + Found(n));
    return v;
  }
  bool Bool(const YAML::Node& n, const std::string& field) const {
    if (!n.IsScalar()) Bad(n, field, "expected true or false" + Found(n));
    try {
      return n.as<bool>();
    } catch (const YAML::Exception&) {
      Bad(n, field, "expected true or false" + Found(n));
    }
  }
  std::string Text(const YAML::Node& n, const std::string& field) const {
    if (!n.IsScalar() || n.Scalar().empty()) Bad(n, field, "expected a text value" + Found(n));
    return n.Scalar();
  }
  // A list of numbers; `count` 0 accepts any non-empty length.
  std::vector<double> Numbers(const YAML::Node& n, const std::string& field, size_t count) const {
    const std::string want = count ? "a list of " + std::to_string(count) + " numbers" : "a list of numbers";
    if (!n.IsSequence() || (count && n.size() != count) || n.size() == 0) Bad(n, field, "expected " + want + Found(n));
    std::vector<double> v;
    for (size_t i = 0; i < n.size(); ++i) v.push_back(Number(n[i], field + "[" + std::to_string(i) + "]"));
    return v;
  }
  Vec3 Vector3(const YAML::Node& n, const std::string& field) const {
    const auto v = Numbers(n, field, 3);
    return {v[0], v[1], v[2]};
  }
  Eigen::Quaterniond Quaternion(const YAML::Node& n, const std::string& field) const {
    const auto v = Numbers(n, field, 4);
    const Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
    // Hand-written quaternions carry 4-5 digits; anything further from unit length is
    // a mistake rather than rounding.
    if (!IsUnitQuaternion(q)) Bad(n, field, "expected a unit quaternion [w, x, y, z]");
    return q.normalized();
  }
  fs::path Path(const YAML::Node& n, const std::string& field) const {
    fs::path p = Text(n, field);
    return p.is_relative() ? base_ / p : p;
  }

 private:
  std::string source_;
  fs::path base_;
};

// Camera pose looking from `position` at `look_at`, image "up" (-y) along `up`.
Pose LookAt(const Vec3& position, const Vec3& look_at, const Vec3& up) {
  const Vec3 z = (look_at - position).normalized();
  const Vec3 x = z.cross(up).normalized();
  const Vec3 y = z.cross(x);
  Mat3 R_rig_cam;
  R_rig_cam << x, y, z;
  return Pose{R_rig_cam, position}.Inverse();  // T_cam_rig
}

std::vector<int> ImagerSize(const Reader& r, const YAML::Node& n, const std::string& field) {
  const std::string want = "expected [width, height] in pixels, integers >= 1";
  if (!n.IsSequence() || n.size() != 2) r.Bad(n, field, want + r.Found(n));
  std::vector<int> s;
  for (size_t i = 0; i < 2; ++i) {
    long long v = 0;
    try {
      v = n[i].as<long long>();
    } catch (const YAML::Exception&) {
      r.Bad(n, field, want + r.Found(n[i]));
    }
    if (v < 1 || v > 100000) r.Bad(n, field, want + r.Found(n[i]));
    s.push_back(static_cast<int>(v));
  }
  return s;
}

// A camera from a lens model name, intrinsics and size; the model's own complaints
// (unknown name, wrong intrinsics count) are reported at `at`.
CameraModel MakeCamera(const Reader& r, const YAML::Node& at, const std::string& field, const std::string& lensmodel,
                       const std::vector<double>& intrinsics, const std::vector<int>& size, const Pose& T_cam_rig) {
  try {
    return CameraModel(lensmodel, intrinsics, size[0], size[1], T_cam_rig);
  } catch (const InputError& e) {
    r.Bad(at, field, e.what());
  }
}

std::vector<std::string> DefaultNames(size_t n) {
  std::vector<std::string> names;
  for (size_t i = 0; i < n; ++i) names.push_back("cam" + std::to_string(i));
  return names;
}

CameraRig ParseInlineRig(const Reader& r, const YAML::Node& n) {
  r.Keys(n, {"cameras"}, "rig");
  const YAML::Node cams = n["cameras"];
  if (!cams.IsSequence() || cams.size() == 0) r.Bad(cams, "rig.cameras", "expected a non-empty list of cameras" + r.Found(cams));
  CameraRig rig;
  for (size_t i = 0; i < cams.size(); ++i) {
    const YAML::Node c = cams[i];
    const std::string f = "rig.cameras[" + std::to_string(i) + "]";
    r.Keys(c, {"name", "model", "lensmodel", "intrinsics", "imagersize", "rt_cam_rig"}, f);
    rig.names.push_back(c["name"] ? r.Text(c["name"], f + ".name") : "cam" + std::to_string(i));
    if (c["model"]) {
      const fs::path model = r.Path(c["model"], f + ".model");
      try {
        rig.cameras.push_back(CameraModel::Read(model));
      } catch (const InputError& e) {
        r.Bad(c["model"], f + ".model", e.what());
      }
      continue;
    }
    const std::string lens = r.Text(r.Require(c, "lensmodel", f, "an mrcal lens model name, or 'model: file'"), f + ".lensmodel");
    const auto intr = r.Numbers(r.Require(c, "intrinsics", f, "[fx, fy, cx, cy, distortion...]"), f + ".intrinsics", 0);
    const auto size = ImagerSize(r, r.Require(c, "imagersize", f, "[width, height] in pixels"), f + ".imagersize");
    Pose T;
    if (c["rt_cam_rig"]) {
      const auto rt = r.Numbers(c["rt_cam_rig"], f + ".rt_cam_rig", 6);
      T = Pose::FromRt(rt.data());
    }
    rig.cameras.push_back(MakeCamera(r, c, f, lens, intr, size, T));
  }
  return rig;
}

CameraRig ParseGeneratedRig(const Reader& r, const YAML::Node& n) {
  r.Keys(n, {"type", "lensmodel", "intrinsics", "imagersize", "look_at_m", "up", "positions_m", "count", "radius_m",
             "height_m", "start_deg", "names"},
         "rig");
  const YAML::Node type_node = n["type"];
  const std::string type = r.Text(type_node, "rig.type");
  std::vector<Vec3> positions;
  if (type == "look_at") {
    const YAML::Node list = r.Require(n, "positions_m", "rig", "the camera centres [[x, y, z], ...]");
    if (!list.IsSequence() || list.size() == 0)
      r.Bad(list, "rig.positions_m", "expected a non-empty list of [x, y, z]" + r.Found(list));
    for (size_t i = 0; i < list.size(); ++i)
      positions.push_back(r.Vector3(list[i], "rig.positions_m[" + std::to_string(i) + "]"));
  } else if (type == "ring") {
    const long long count = r.Integer(r.Require(n, "count", "rig", "number of cameras"), "rig.count", 1);
    const double radius = r.Positive(r.Require(n, "radius_m", "rig", "ring radius"), "rig.radius_m");
    const double height = r.Number(r.Require(n, "height_m", "rig", "height of the cameras"), "rig.height_m");
    const double start = n["start_deg"] ? r.Number(n["start_deg"], "rig.start_deg") : 0.0;
    if (count > 1000) r.Bad(n["count"], "rig.count", "expected at most 1000 cameras");
    for (long long i = 0; i < count; ++i) {
      const double az = (start + 360.0 * static_cast<double>(i) / static_cast<double>(count)) * std::numbers::pi / 180.0;
      positions.emplace_back(radius * std::cos(az), radius * std::sin(az), height);
    }
  } else {
    r.Bad(type_node, "rig.type", "expected look_at or ring" + r.Found(type_node));
  }
  const std::string lens = r.Text(r.Require(n, "lensmodel", "rig", "an mrcal lens model name"), "rig.lensmodel");
  const auto intr = r.Numbers(r.Require(n, "intrinsics", "rig", "[fx, fy, cx, cy, distortion...]"), "rig.intrinsics", 0);
  const auto size = ImagerSize(r, r.Require(n, "imagersize", "rig", "[width, height] in pixels"), "rig.imagersize");
  const Vec3 look = r.Vector3(r.Require(n, "look_at_m", "rig", "the point every camera looks at"), "rig.look_at_m");
  const Vec3 up = n["up"] ? r.Vector3(n["up"], "rig.up") : Vec3::UnitZ();
  if (up.norm() < 1e-9) r.Bad(n["up"], "rig.up", "expected a non-zero direction");
  CameraRig rig;
  rig.names = DefaultNames(positions.size());
  if (const YAML::Node names = n["names"]) {
    if (!names.IsSequence() || names.size() != positions.size())
      r.Bad(names, "rig.names", "expected a list of " + std::to_string(positions.size()) + " camera names" + r.Found(names));
    for (size_t i = 0; i < names.size(); ++i) rig.names[i] = r.Text(names[i], "rig.names[" + std::to_string(i) + "]");
  }
  for (size_t i = 0; i < positions.size(); ++i) {
    const Vec3 z = look - positions[i];
    if (z.norm() < 1e-9 || z.normalized().cross(up.normalized()).norm() < 1e-6)
      r.Bad(n, "rig", "camera " + std::to_string(i) + " sits on look_at_m or looks along 'up'");
    rig.cameras.push_back(MakeCamera(r, n, "rig", lens, intr, size, LookAt(positions[i], look, up)));
  }
  return rig;
}

CameraRig ParseRig(const Reader& r, const YAML::Node& n) {
  if (n.IsScalar()) {
    const fs::path file = r.Path(n, "rig");
    try {
      return CameraRig::Read(file);
    } catch (const InputError& e) {
      r.Bad(n, "rig", e.what());
    }
  }
  const auto Checked = [&](CameraRig rig) {
    try {
      rig.CheckBaselines("rig");
    } catch (const InputError& e) {
      r.Bad(n, "rig", e.what());
    }
    return rig;
  };
  if (n.IsMap() && n["cameras"]) return Checked(ParseInlineRig(r, n));
  if (n.IsMap() && n["type"]) return Checked(ParseGeneratedRig(r, n));
  r.Bad(n, "rig", "expected a rig file name, a map with 'cameras', or a generator map with 'type'" + r.Found(n));
}

Target ParseTarget(const Reader& r, const YAML::Node& n) {
  if (n.IsScalar()) {
    if (n.Scalar() == "default") return Target::Default();
    const fs::path file = r.Path(n, "target");
    try {
      return Target::Read(file);
    } catch (const InputError& e) {
      r.Bad(n, "target", e.what());
    }
  }
  r.Keys(n, {"name", "ball_radius_m", "balls_m"}, "target");
  Target t;
  if (n["name"]) t.name = r.Text(n["name"], "target.name");
  t.ball_radius = r.Positive(r.Require(n, "ball_radius_m", "target", "ball radius in metres"), "target.ball_radius_m");
  const YAML::Node balls = r.Require(n, "balls_m", "target", "ball centres [[x, y, z], ...] in the target frame");
  if (!balls.IsSequence() || balls.size() == 0)
    r.Bad(balls, "target.balls_m", "expected a non-empty list of [x, y, z]" + r.Found(balls));
  t.balls_target.clear();
  for (size_t i = 0; i < balls.size(); ++i)
    t.balls_target.push_back(r.Vector3(balls[i], "target.balls_m[" + std::to_string(i) + "]"));
  // Balls that overlap cannot be rendered as separate spheres (the tracker refuses such a
  // target too, as a target file is refused when read).
  if (t.balls_target.size() >= 3) {
    try {
      t.MinDistanceGap();
    } catch (const InputError& e) {
      r.Bad(balls, "target.balls_m", e.what());
    }
  }
  return t;
}

void ParseExplicitMotion(const Reader& r, const YAML::Node& n, Scenario* s) {
  r.Keys(n, {"type", "rate_hz", "poses"}, "motion");
  const YAML::Node poses = n["poses"];
  if (!poses.IsSequence() || poses.size() == 0)
    r.Bad(poses, "motion.poses", "expected a non-empty list of {t_m, q_wxyz, time_s}" + r.Found(poses));
  std::optional<double> rate;
  if (n["rate_hz"]) rate = r.Rate(n["rate_hz"], "motion.rate_hz");
  for (size_t i = 0; i < poses.size(); ++i) {
    const YAML::Node p = poses[i];
    const std::string f = "motion.poses[" + std::to_string(i) + "]";
    r.Keys(p, {"time_s", "t_m", "q_wxyz"}, f);
    const Vec3 t = r.Vector3(r.Require(p, "t_m", f, "target position [x, y, z] in the rig frame"), f + ".t_m");
    const auto q = r.Quaternion(r.Require(p, "q_wxyz", f, "target orientation [w, x, y, z]"), f + ".q_wxyz");
    double time;
    if (p["time_s"]) {
      time = r.Number(p["time_s"], f + ".time_s");
    } else {
      if (!rate) r.Require(n, "rate_hz", "motion", "frame rate, needed when a pose has no time_s");
      time = static_cast<double>(i) / *rate;
    }
    if (!s->times.empty() && !(time > s->times.back()))
      r.Bad(p, f + ".time_s", "expected times increasing from pose to pose");
    s->times.push_back(time);
    s->T_rig_target.push_back(Pose::FromQuaternion(q, t));
  }
}

void ParseLissajous(const Reader& r, const YAML::Node& n, Scenario* s) {
  r.Keys(n, {"type", "frames", "rate_hz", "start_s", "centre_m", "amplitude_m", "period_s", "phase_rad",
             "rotation_amplitude_deg", "rotation_period_s", "rotation_phase_rad", "base_q_wxyz"},
         "motion");
  const long long frames = r.Integer(r.Require(n, "frames", "motion", "number of frames"), "motion.frames", 1);
  if (frames > 10000000) r.Bad(n["frames"], "motion.frames", "expected at most 10000000 frames");
  const double rate = r.Rate(r.Require(n, "rate_hz", "motion", "frame rate in Hz"), "motion.rate_hz");
  const double start = n["start_s"] ? r.Number(n["start_s"], "motion.start_s") : 0.0;
  const Vec3 centre = r.Vector3(r.Require(n, "centre_m", "motion", "centre of the path"), "motion.centre_m");
  const Vec3 amp = r.Vector3(r.Require(n, "amplitude_m", "motion", "half extent of the path"), "motion.amplitude_m");
  // A path beyond any rig's range is a unit mistake (mm as m) and would print truth
  // coordinates no camera sees.
  if (!(centre.cwiseAbs().maxCoeff() <= kMaxRigRangeM))
    r.Bad(n["centre_m"], "motion.centre_m", "expected a centre within " + std::to_string(int(kMaxRigRangeM)) +
                                                " m of the rig (metres, not mm)");
  if (!(amp.cwiseAbs().maxCoeff() <= kMaxRigRangeM))
    r.Bad(n["amplitude_m"], "motion.amplitude_m", "expected half extents within " +
                                                      std::to_string(int(kMaxRigRangeM)) + " m (metres, not mm)");
  const YAML::Node period_node = r.Require(n, "period_s", "motion", "periods of x, y, z in seconds");
  const Vec3 period = r.Vector3(period_node, "motion.period_s");
  if (!(period.minCoeff() > 0)) r.Bad(period_node, "motion.period_s", "expected three periods > 0");
  const Vec3 phase = n["phase_rad"] ? r.Vector3(n["phase_rad"], "motion.phase_rad") : Vec3::Zero();
  double rot_amp = 0.0;
  Vec3 rot_period = Vec3::Ones(), rot_phase = Vec3::Zero();
  if (n["rotation_amplitude_deg"]) {
    rot_amp = r.Number(n["rotation_amplitude_deg"], "motion.rotation_amplitude_deg");
    if (rot_amp < 0 || rot_amp >= 180)
      r.Bad(n["rotation_amplitude_deg"], "motion.rotation_amplitude_deg", "expected an angle in [0, 180) degrees");
    rot_amp *= std::numbers::pi / 180.0;
  }
  if (rot_amp > 0) {
    const YAML::Node rp = r.Require(n, "rotation_period_s", "motion", "periods of the orientation wobble");
    rot_period = r.Vector3(rp, "motion.rotation_period_s");
    if (!(rot_period.minCoeff() > 0)) r.Bad(rp, "motion.rotation_period_s", "expected three periods > 0");
  }
  if (n["rotation_phase_rad"]) rot_phase = r.Vector3(n["rotation_phase_rad"], "motion.rotation_phase_rad");
  const Eigen::Quaterniond base =
      n["base_q_wxyz"] ? r.Quaternion(n["base_q_wxyz"], "motion.base_q_wxyz") : Eigen::Quaterniond::Identity();
  const Mat3 R_base = base.toRotationMatrix();
  for (long long i = 0; i < frames; ++i) {
    const double t = start + static_cast<double>(i) / rate;
    Vec3 p, w;
    for (int k = 0; k < 3; ++k) {
      p[k] = centre[k] + amp[k] * std::sin(2 * std::numbers::pi * t / period[k] + phase[k]);
      // Each component within a / sqrt(3), so the rotation angle |w| stays within a.
      w[k] = rot_amp / std::sqrt(3.0) * std::sin(2 * std::numbers::pi * t / rot_period[k] + rot_phase[k]);
    }
    s->times.push_back(t);
    s->T_rig_target.push_back(Pose{ExpSO3(w) * R_base, p});
  }
}

void ParseMotion(const Reader& r, const YAML::Node& n, Scenario* s) {
  r.RequireMap(n, "motion");
  if (n["poses"]) {
    if (n["type"] && n["type"].Scalar() != "poses")
      r.Bad(n["type"], "motion.type", "a motion with 'poses' has type poses (or none)" + r.Found(n["type"]));
    ParseExplicitMotion(r, n, s);
    return;
  }
  const YAML::Node type = r.Require(n, "type", "motion", "lissajous, or give 'poses'");
  if (r.Text(type, "motion.type") != "lissajous") r.Bad(type, "motion.type", "expected lissajous or poses" + r.Found(type));
  ParseLissajous(r, n, s);
}

RenderOptions ParseRender(const Reader& r, const YAML::Node& n) {
  r.Keys(n, {"bit_depth", "exposure", "ball_dn", "background_dn", "background_gradient_dn", "blur_sigma_px",
             "gain_e_per_dn", "read_noise_dn", "supersampling", "spurious_per_image", "spurious_radius_px",
             "spurious_dn", "occlusion_probability", "dropout_probability", "noise_free"},
         "render");
  RenderOptions o;
  auto num = [&](const char* key, double* v) {
    if (n[key]) *v = r.Number(n[key], Join("render", key));
  };
  if (n["bit_depth"]) {
    o.bit_depth = static_cast<int>(r.Integer(n["bit_depth"], "render.bit_depth", 1));
    if (o.bit_depth != 8 && o.bit_depth != 16) r.Bad(n["bit_depth"], "render.bit_depth", "expected 8 or 16" + r.Found(n["bit_depth"]));
  }
  num("exposure", &o.exposure);
  num("ball_dn", &o.ball_dn);
  num("background_dn", &o.background_dn);
  if (n["background_gradient_dn"]) {
    const auto g = r.Numbers(n["background_gradient_dn"], "render.background_gradient_dn", 2);
    o.background_gradient_dn = Vec2(g[0], g[1]);
  }
  num("blur_sigma_px", &o.blur_sigma_px);
  num("gain_e_per_dn", &o.gain_e_per_dn);
  num("read_noise_dn", &o.read_noise_dn);
  if (n["supersampling"]) o.supersampling = static_cast<int>(r.Integer(n["supersampling"], "render.supersampling", 1));
  num("spurious_per_image", &o.spurious_per_image);
  if (n["spurious_radius_px"]) {
    const auto s = r.Numbers(n["spurious_radius_px"], "render.spurious_radius_px", 2);
    o.spurious_radius_min_px = s[0];
    o.spurious_radius_max_px = s[1];
  }
  num("spurious_dn", &o.spurious_dn);
  num("occlusion_probability", &o.occlusion_probability);
  num("dropout_probability", &o.dropout_probability);
  if (n["noise_free"]) o.noise_free = r.Bool(n["noise_free"], "render.noise_free");
  std::string why;
  if (!o.IsValid(&why)) r.Bad(n, "render", why);
  return o;
}

// Shortest text that reads back as the same double.
std::string Num(double v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, res.ptr);
}
std::vector<std::string> Nums(const double* v, size_t n) {
  std::vector<std::string> out;
  for (size_t i = 0; i < n; ++i) out.push_back(Num(v[i]));
  return out;
}
std::vector<std::string> Nums(const std::vector<double>& v) { return Nums(v.data(), v.size()); }

bool SafeName(const std::string& n) {
  if (n.empty() || n == "." || n == "..") return false;
  for (char c : n)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) return false;
  return true;
}

}  // namespace

Scenario Scenario::Parse(const std::string& text, const std::string& source, const fs::path& base_dir) {
  YAML::Node root;
  try {
    root = LoadYaml(text, source);
  } catch (const YAML::ParserException& e) {
    Throw(source, " line ", e.mark.line + 1, ": not valid YAML or JSON: ", e.msg);
  }
  const Reader r(source, base_dir);
  if (!root.IsMap()) Throw(source, ": expected a scenario map with fields rig, target and motion (and seed, render)");
  Scenario s;
  try {
    r.Keys(root, {"seed", "rig", "target", "motion", "render"}, "");
    if (root["seed"]) s.seed = r.Unsigned64(root["seed"], "seed");
    s.rig = ParseRig(r, r.Require(root, "rig", "", "the cameras: a rig file, inline cameras or a generator"));
    s.target = ParseTarget(r, r.Require(root, "target", "", "default, a target file, or inline"));
    ParseMotion(r, r.Require(root, "motion", "", "the target's poses over time"), &s);
    if (root["render"]) s.render = ParseRender(r, root["render"]);
  } catch (const YAML::Exception& e) {
    // Anything the typed readers did not anticipate still names the file.
    if (e.mark.is_null()) Throw(source, ": ", e.msg);
    Throw(source, " line ", e.mark.line + 1, ": ", e.msg);
  }
  std::string why;
  if (!s.IsValid(&why)) Throw(source, ": ", why);
  return s;
}

Scenario Scenario::Read(const fs::path& path) {
  if (!fs::exists(path)) Throw("scenario file ", path.string(), " does not exist");
  return Parse(ReadTextFile(path), path.string(), path.parent_path());
}

const std::string& Scenario::DefaultText() {
  static const std::string text = kDefaultScenario;
  return text;
}

// The default text names no files, so no base folder is needed.
Scenario Scenario::Default() { return Parse(DefaultText(), "<default scenario>", fs::path()); }

std::string Scenario::ToYaml() const {
  YAML::Emitter out;
  out << YAML::Comment("mcms synthetic scenario (effective: every camera, ball and pose written out)");
  out << YAML::BeginMap;
  out << YAML::Key << "seed" << YAML::Value << seed;

  out << YAML::Key << "rig" << YAML::Value << YAML::BeginMap << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  for (size_t i = 0; i < rig.size(); ++i) {
    const CameraModel& c = rig.cameras[i];
    double rt[6];
    c.T_cam_rig().ToRt(rt);
    out << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << rig.names[i];
    out << YAML::Key << "lensmodel" << YAML::Value << c.LensModelName();
    out << YAML::Key << "intrinsics" << YAML::Value << YAML::Flow << Nums(c.Intrinsics());
    out << YAML::Key << "imagersize" << YAML::Value << YAML::Flow << std::vector<int>{c.Width(), c.Height()};
    out << YAML::Key << "rt_cam_rig" << YAML::Value << YAML::Flow << Nums(rt, 6);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;

  out << YAML::Key << "target" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "name" << YAML::Value << target.name;
  out << YAML::Key << "ball_radius_m" << YAML::Value << Num(target.ball_radius);
  out << YAML::Key << "balls_m" << YAML::Value << YAML::BeginSeq;
  for (const Vec3& b : target.balls_target) out << YAML::Flow << Nums(b.data(), 3);
  out << YAML::EndSeq << YAML::EndMap;

  out << YAML::Key << "motion" << YAML::Value << YAML::BeginMap << YAML::Key << "poses" << YAML::Value
      << YAML::BeginSeq;
  for (size_t i = 0; i < times.size(); ++i) {
    const Pose& T = T_rig_target[i];
    const Eigen::Quaterniond q = T.Quaternion();
    const double qv[4] = {q.w(), q.x(), q.y(), q.z()};
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "time_s" << YAML::Value << Num(times[i]);
    out << YAML::Key << "t_m" << YAML::Value << YAML::Flow << Nums(T.t.data(), 3);
    out << YAML::Key << "q_wxyz" << YAML::Value << YAML::Flow << Nums(qv, 4);
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;

  const RenderOptions& o = render;
  out << YAML::Key << "render" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "bit_depth" << YAML::Value << o.bit_depth;
  out << YAML::Key << "exposure" << YAML::Value << Num(o.exposure);
  out << YAML::Key << "ball_dn" << YAML::Value << Num(o.ball_dn);
  out << YAML::Key << "background_dn" << YAML::Value << Num(o.background_dn);
  out << YAML::Key << "background_gradient_dn" << YAML::Value << YAML::Flow << Nums(o.background_gradient_dn.data(), 2);
  out << YAML::Key << "blur_sigma_px" << YAML::Value << Num(o.blur_sigma_px);
  out << YAML::Key << "gain_e_per_dn" << YAML::Value << Num(o.gain_e_per_dn);
  out << YAML::Key << "read_noise_dn" << YAML::Value << Num(o.read_noise_dn);
  out << YAML::Key << "supersampling" << YAML::Value << o.supersampling;
  out << YAML::Key << "spurious_per_image" << YAML::Value << Num(o.spurious_per_image);
  const double sr[2] = {o.spurious_radius_min_px, o.spurious_radius_max_px};
  out << YAML::Key << "spurious_radius_px" << YAML::Value << YAML::Flow << Nums(sr, 2);
  out << YAML::Key << "spurious_dn" << YAML::Value << Num(o.spurious_dn);
  out << YAML::Key << "occlusion_probability" << YAML::Value << Num(o.occlusion_probability);
  out << YAML::Key << "dropout_probability" << YAML::Value << Num(o.dropout_probability);
  out << YAML::Key << "noise_free" << YAML::Value << o.noise_free;
  out << YAML::EndMap;
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

void Scenario::Write(const fs::path& path) const {
  std::string why;
  if (!IsValid(&why)) Throw("cannot write scenario ", path.string(), ": ", why);
  const std::string text = ToYaml();
  WriteFileAtomically(path, [&](std::ostream& o) { o << text; });
}

bool Scenario::IsValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (rig.size() == 0) return fail("the rig has no cameras");
  if (rig.names.size() != rig.cameras.size()) return fail("the rig needs one name per camera");
  std::set<std::string> seen;
  for (size_t i = 0; i < rig.size(); ++i) {
    const std::string& n = rig.names[i];
    if (!SafeName(n))
      return fail("camera name '" + n + "' must be a folder name of letters, digits, '_', '-' or '.'");
    if (n.size() > kMaxCameraNameLength)
      return fail("camera name '" + n.substr(0, 20) + "...' has " + std::to_string(n.size()) +
                  " characters, at most " + std::to_string(kMaxCameraNameLength) + " (it names the camera's image folder)");
    if (!seen.insert(n).second) return fail("camera name '" + n + "' is used twice");
    if (rig.cameras[i].Width() <= 0 || rig.cameras[i].Height() <= 0)
      return fail("camera '" + n + "' has an image size of 0");
  }
  if (!(target.ball_radius > 0) || !std::isfinite(target.ball_radius)) return fail("the ball radius must be positive");
  if (target.balls_target.empty()) return fail("the target has no balls");
  for (const Vec3& b : target.balls_target)
    if (!b.allFinite()) return fail("a ball centre is not finite");
  if (times.empty()) return fail("the scenario has no frames");
  if (times.size() != T_rig_target.size()) return fail("the scenario needs one pose per frame time");
  for (size_t i = 0; i < times.size(); ++i) {
    if (!std::isfinite(times[i])) return fail("frame " + std::to_string(i) + " has a non-finite time");
    if (i > 0 && !(times[i] > times[i - 1])) return fail("frame times must increase strictly");
    const Pose& T = T_rig_target[i];
    if (!T.t.allFinite() || !T.R.allFinite() || (T.R.transpose() * T.R - Mat3::Identity()).norm() > 1e-9 ||
        T.R.determinant() < 0)
      return fail("the pose of frame " + std::to_string(i) + " is not a finite rigid transform");
  }
  std::string r_why;
  if (!render.IsValid(&r_why)) return fail("render options: " + r_why);
  return true;
}

}  // namespace mcms
