// Do the sensors agree within their covariances? A chi-square test of their disagreement,
// so that a sensor that is off (a bumped camera, a robot with a bad joint offset) is
// flagged instead of being averaged into the fused estimate.
//
// The statistic. For a set S of Gaussian measurements (information L_i, measured value b_i
// on a common tangent), the minimum of the weighted residual
//     chi2(S) = min_x sum_{i in S} (x - b_i)^T L_i (x - b_i)
// is chi-square distributed with dof(S) = sum_i rank(L_i) - rank(sum_i L_i) degrees of
// freedom when the measurements are consistent (total test).
// Per sensor, the increase of that residual when sensor i joins the others,
//     nis_i = chi2(S) - chi2(S \ i),   dof_i = dof(S) - dof(S \ i),
// is the sensor's normalized innovation squared against the fused estimate of the others
// (exactly the leave-one-out NIS (b_i - x_others)^T (P_i + P_others)^-1 (b_i - x_others)
// when both are full rank), chi-square with dof_i degrees of freedom. It stays defined
// when the others alone leave directions unobserved (then dof_i < rank(L_i)), and it is 0
// with dof_i = 0 for a sensor nothing else can be compared with.
//
// Attribution. Leave-one-out statistics of good sensors also grow when one sensor is off,
// since the others' fused estimate contains the bad one. The report therefore also runs a
// greedy isolation: while the remaining set fails the total test and has at least three
// members, exclude the sensor with the smallest p-value and retest. With only two sensors
// (or when the disagreement lies along a direction only two sensors observe, e.g. yaw
// between camera and robot when the third is an inclinometer) the disagreement cannot be
// attributed; the report says so (`attributed` false).
#pragma once

#include <string>
#include <vector>

#include "fusion/moifa.h"

namespace mcms {

struct ConsistencyOptions {
  double significance = 0.01;  // flag when p-value < significance; in (0, 1)
  bool IsValid(std::string* why = nullptr) const;
};

struct SensorConsistency {
  std::string name;
  double nis = 0.0;      // chi2(all) - chi2(all but this sensor)
  int dof = 0;           // degrees of freedom the sensor adds to the test
  double p_value = 1.0;  // P(chi2(dof) > nis); 1 when dof = 0
  bool flagged = false;  // p_value < significance
};

struct ConsistencyReport {
  double chi2 = 0.0;     // total weighted residual of all sensors
  int dof = 0;
  double p_value = 1.0;
  bool consistent = true;                  // p_value >= significance
  std::vector<SensorConsistency> sensors;  // input order
  std::vector<int> excluded;               // greedy isolation, in order of exclusion
  bool attributed = true;  // after excluding `excluded`, the rest passes the total test
};

// Positions: measured values and information as given (linear model).
ConsistencyReport CheckConsistency(const std::vector<PositionMeasurement>& measurements,
                                   const ConsistencyOptions& options = {});
// Poses: linearized at the fused pose of all measurements (FusePoses with fuse_options).
// InputError when the measurements cannot be fused (singular total information).
ConsistencyReport CheckConsistency(const std::vector<PoseMeasurement>& measurements,
                                   const ConsistencyOptions& options = {}, const FusePosesOptions& fuse_options = {});

}  // namespace mcms
