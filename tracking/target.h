// The five-ball target: ball centres in the target frame (metres) and the ball radius.
// Five balls with five-plus distinct pairwise distances, so no permutation of the balls
// maps the target onto itself and its identity and pose are unique.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "vision/camera_model.h"

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

// The balls whose images `cam` sees crowded, with the target at T_rig_target: another
// ball's image comes nearer than gap_px + gap_radii * (r_b + r_o) outline to outline (r the
// apparent radius f * R / z), so that the two discs may merge into one blob, one may hide
// part of the other, or the other's light falls in this one's measurement window and
// background ring: a detected centre is pulled away from the ball's. The tracker does not
// count such a ball as missing (gap_radii 1: centres within two diameters); the camera audit
// does not test it (gap_px: the detector's window margin plus its ring). A limit of the
// detector, not a fault of the camera model. Balls behind the camera are never crowded.
std::vector<bool> CrowdedBallImages(const CameraModel& cam, const Target& target, const Pose& T_rig_target,
                                    double gap_px, double gap_radii = 0.0);

}  // namespace mcms
