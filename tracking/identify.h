// Identification of the five-ball target among triangulated points by its distance
// signature, and the closed-form rigid fit that starts the bundle adjustment.
#pragma once

#include <optional>
#include <vector>

#include "core/pose_math.h"
#include "tracking/target.h"
#include "vision/triangulation.h"

namespace mcms {

struct IdentificationOptions {
  double distance_sigma_floor_m = 0.0005;  // added in quadrature to the points' own distance sigma
  double gate_sigma = 5.0;                 // a pair distance further than this many sigma is impossible
  int max_missing = 1;                     // balls that may be absent (occluded, not triangulated)
  double missing_penalty = 25.0;           // chi-square cost of one missing ball (a 5-sigma miss)
  bool IsValid(std::string* why) const;
};

struct Identification {
  std::vector<int> point_of_ball;  // index into the points, -1 where the ball was not found
  int balls_found = 0;
  double cost = 0;                 // chi-square of the distance residuals + missing penalties
  // How much better the chosen assignment fits than the next best (chi-square units);
  // +infinity when no other assignment is possible at all.
  double margin = 0;
  Pose T_rig_target;               // closed-form rigid fit of the target to the found balls
  double fit_rms_m = 0;            // RMS distance of the fitted balls from their points
};

// Assigns target balls to points (each point used once, at most max_missing balls
// absent, extra points ignored), minimizing the chi-square of the pairwise distance
// residuals, with the distance sigma propagated from the points' covariances.
// nullopt when fewer than 3 balls can be assigned consistently.
std::optional<Identification> IdentifyTarget(const Target& target, const std::vector<TriangulatedPoint>& points,
                                             const IdentificationOptions& options = {});

// Least-squares rigid transform T with b_i ~ T * a_i (Kabsch/Umeyama without scale).
Pose FitRigid(const std::vector<Vec3>& a, const std::vector<Vec3>& b);

}  // namespace mcms
