// ISO 9283:1998 performance characteristics of industrial robots from repeated
// measurements: pose accuracy and repeatability (AP, RP; clause 7.2), distance accuracy
// and repeatability (AD, RD; 7.5), path accuracy and repeatability (AT, RT; 8.2).
//
// Formulas (n attained measurements of one commanded pose c, positions x_j):
//   barycentre  x_bar = (1/n) sum x_j
//   AP_p = |x_bar - x_c|,  AP_x = x_bar - x_c (likewise y, z)
//   l_j = |x_j - x_bar|,  l_bar = (1/n) sum l_j,  S_l = sqrt(sum (l_j - l_bar)^2 / (n - 1))
//   RP_l = l_bar + 3 S_l
// Orientation: the standard compares the rotation angles (a, b, c) about the base x, y, z
// axes. Here each attained orientation enters as its small rotation from the commanded
// one in the base frame, (da, db, dc)_j = Log(R_j R_c^T) (the project's dtheta, which
// equals (a_j - a_c, b_j - b_c, c_j - c_c) to first order for the sub-degree deviations
// ISO 9283 measures, and has no Euler-angle singularity):
//   AP_a = mean(da_j),  RP_a = 3 S_a, S_a = sqrt(sum (da_j - mean)^2 / (n - 1))   (b, c alike)
// Distance (poses P1, P2 reached in the same n cycles): D_j = |x_1j - x_2j|, D_c = |x_c1 - x_c2|,
//   AD_p = D_bar - D_c,  RD_p = 3 S_D, S_D = sqrt(sum (D_j - D_bar)^2 / (n - 1));
//   per axis D_xj = x_1j - x_2j: AD_x = D_x_bar - D_cx, RD_x = 3 S_Dx (likewise y, z).
// Path (8.2): at each calculation point c_i of the commanded path, the plane normal to the
//   commanded path through c_i is intersected with each of the n attained paths (the
//   crossing nearest c_i); G_i is the barycentre of the n crossings:
//   AT_p = max_i |G_i - c_i|,  RT_p = max_i (l_bar_i + 3 S_li) with l_ij = |x_ij - G_i|.
// Units: the inputs' (SI in this project: m, rad); RP and RD are the "+-" half-widths.
// Not covered: the orientation parts of the distance and path characteristics, and the
// cornering, stabilization and drift characteristics.
#pragma once

#include <vector>

#include "core/pose_math.h"

namespace mcms {

struct PoseCharacteristics {
  int n = 0;
  Vec3 barycentre = Vec3::Zero();
  double AP_p = 0.0;
  Vec3 AP_xyz = Vec3::Zero();
  double AP_a = 0.0, AP_b = 0.0, AP_c = 0.0;
  double l_bar = 0.0, S_l = 0.0, RP_l = 0.0;
  double RP_a = 0.0, RP_b = 0.0, RP_c = 0.0;
};
// InputError for fewer than 2 attained poses.
PoseCharacteristics PoseAccuracyRepeatability(const Pose& commanded, const std::vector<Pose>& attained);

struct DistanceCharacteristics {
  int n = 0;
  double D_c = 0.0, D_bar = 0.0;
  double AD_p = 0.0, S_D = 0.0, RD_p = 0.0;
  Vec3 AD_xyz = Vec3::Zero(), RD_xyz = Vec3::Zero();
};
// attained1[j] and attained2[j] are the same cycle j. InputError on different counts or
// fewer than 2 cycles.
DistanceCharacteristics DistanceAccuracyRepeatability(const Pose& commanded1, const Pose& commanded2,
                                                      const std::vector<Pose>& attained1,
                                                      const std::vector<Pose>& attained2);

struct PathCharacteristics {
  double AT_p = 0.0, RT_p = 0.0;
  std::vector<double> AT_i, RT_i;  // per calculation point
  std::vector<Vec3> barycentres;
};
// `commanded` is the commanded path as a polyline whose vertices are the calculation
// points (at least 2, consecutive points distinct); `attained` holds n >= 2 measured runs,
// each a polyline. InputError naming the run and the point when a run never crosses a
// normal plane.
PathCharacteristics PathAccuracyRepeatability(const std::vector<Vec3>& commanded,
                                              const std::vector<std::vector<Vec3>>& attained);

}  // namespace mcms
