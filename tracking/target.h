// The five-ball target: ball centres in the target frame (metres) and the ball radius.
// Five balls with five-plus distinct pairwise distances, so no permutation of the balls
// maps the target onto itself and its identity and pose are unique.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/pose_math.h"

namespace mcms {

struct Target {
  std::string name = "five-ball";
  std::vector<Vec3> balls_target;  // ball centres, target frame, metres
  double ball_radius = 0.0125;     // metres

  // The default target: five balls on a 3-D frame about 0.25 m across, all ten
  // pairwise distances distinct by at least 11 mm.
  static Target Default();
  // YAML: name, ball_radius_m, balls_m: [[x,y,z], ...]. InputError naming the file.
  static Target Read(const std::filesystem::path& path);
  void Write(const std::filesystem::path& path) const;
  // Smallest difference between two of the pairwise distances (m): how distinct the
  // distance signature is. InputError when fewer than 3 balls or two coincide.
  double MinDistanceGap() const;
};

}  // namespace mcms
