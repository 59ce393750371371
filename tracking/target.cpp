#include "tracking/target.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/io.h"
#include "core/yaml.h"

namespace mcms {

Target Target::Default() {
  Target t;
  // Found by a random search for the largest smallest gap between the ten distances
  // (11.6 mm here) with every ball at least 74 mm from every other.
  t.balls_target = {Vec3(0.000, 0.000, 0.000), Vec3(-0.095, 0.090, -0.090), Vec3(0.080, -0.010, -0.055),
                    Vec3(-0.055, -0.090, 0.030), Vec3(0.095, 0.060, -0.075)};
  return t;
}

double Target::MinDistanceGap() const {
  if (balls_target.size() < 3) Throw("target '", name, "' needs at least 3 balls, has ", balls_target.size());
  std::vector<double> d;
  for (size_t i = 0; i < balls_target.size(); ++i)
    for (size_t j = i + 1; j < balls_target.size(); ++j) {
      const double dij = (balls_target[i] - balls_target[j]).norm();
      if (dij < 2.0 * ball_radius) Throw("target '", name, "': balls ", i, " and ", j, " overlap");
      d.push_back(dij);
    }
  std::sort(d.begin(), d.end());
  double gap = std::numeric_limits<double>::infinity();
  for (size_t i = 1; i < d.size(); ++i) gap = std::min(gap, d[i] - d[i - 1]);
  return gap;
}

Target Target::Read(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) Throw("target file ", path.string(), " does not exist");
  Target t;
  try {
    const YAML::Node root = LoadYaml(ReadTextFile(path), "target file " + path.string());
    if (!root.IsMap()) Throw(path.string(), ": expected a YAML map with ball_radius_m and balls_m");
    if (root["name"]) t.name = root["name"].as<std::string>();
    if (!root["ball_radius_m"]) Throw(path.string(), ": missing field 'ball_radius_m'");
    t.ball_radius = root["ball_radius_m"].as<double>();
    const YAML::Node balls = root["balls_m"];
    if (!balls || !balls.IsSequence()) Throw(path.string(), ": missing list 'balls_m' of [x, y, z] in metres");
    t.balls_target.clear();
    for (const auto& b : balls) {
      const auto v = b.as<std::vector<double>>();
      if (v.size() != 3) Throw(path.string(), " line ", b.Mark().line + 1, ": each ball needs [x, y, z]");
      for (size_t k = 0; k < 3; ++k)
        if (!std::isfinite(v[k]) || std::abs(v[k]) > 100.0)
          Throw(path.string(), " line ", b.Mark().line + 1, ": ball ", t.balls_target.size(), " has ", "xyz"[k], " = ",
                v[k], " m; expected a finite position within 100 m of the target origin");
      t.balls_target.emplace_back(v[0], v[1], v[2]);
    }
  } catch (const YAML::Exception& e) {
    Throw("cannot parse target file ", path.string(), ": ", e.what());
  }
  if (!(t.ball_radius > 0) || !std::isfinite(t.ball_radius) || t.ball_radius > 10.0)
    Throw(path.string(), ": ball_radius_m must be a positive finite number of metres (at most 10), found ",
          t.ball_radius);
  try {
    t.MinDistanceGap();
  } catch (const InputError& e) {
    Throw(path.string(), ": ", e.what());
  }
  return t;
}

void Target::Write(const std::filesystem::path& path) const {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap << YAML::Key << "name" << YAML::Value << name;
  out << YAML::Key << "ball_radius_m" << YAML::Value << ball_radius;
  out << YAML::Key << "balls_m" << YAML::Value << YAML::BeginSeq;
  for (const auto& b : balls_target) out << YAML::Flow << std::vector<double>{b.x(), b.y(), b.z()};
  out << YAML::EndSeq << YAML::EndMap;
  const std::string text = out.c_str();
  WriteFileAtomically(path, [&](std::ostream& o) { o << text << "\n"; });
}

std::vector<bool> CrowdedBallImages(const CameraModel& cam, const Target& target, const Pose& T_rig_target,
                                    double gap_px, double gap_radii) {
  const size_t nb = target.balls_target.size();
  std::vector<Vec2> q(nb);
  std::vector<double> radius(nb, -1.0);
  for (size_t b = 0; b < nb; ++b) {
    const Vec3 p_cam = cam.T_cam_rig() * (T_rig_target * target.balls_target[b]);
    if (!(p_cam.z() > 0.0)) continue;
    q[b] = cam.Project(p_cam);
    radius[b] = cam.Intrinsics()[0] * target.ball_radius / p_cam.z();
  }
  std::vector<bool> crowded(nb, false);
  for (size_t b = 0; b < nb; ++b)
    for (size_t o = 0; o < nb && radius[b] > 0; ++o)
      crowded[b] = crowded[b] || (o != b && radius[o] > 0 &&
                                  (q[o] - q[b]).norm() < gap_px + (1.0 + gap_radii) * (radius[b] + radius[o]));
  return crowded;
}

}  // namespace mcms
