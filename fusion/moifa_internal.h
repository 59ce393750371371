// Internal to fusion/: a pose measurement expressed on the tangent of another point.
#pragma once

#include "fusion/moifa.h"

namespace mcms::internal {

struct LinearizedPose {
  Mat6 information;         // on the tangent at T_lin
  Vec6 information_vector;  // on the tangent at T_lin
  Vec6 value;               // the measured tangent vector b with information * b = information_vector
                            // (minimum-norm for a partial measurement); filled when asked for
};

// With x = BoxMinus(T, T_lin) and x_m = BoxMinus(T, T_ref) = delta + A x to first order in x,
// delta = BoxMinus(T_lin, T_ref) and A = diag(J_l(delta_theta)^-1, I) (SO(3) left Jacobian),
// the measurement's cost becomes 1/2 x^T A^T L A x - (A^T (eta - L delta))^T x + const.
LinearizedPose Linearize(const PoseMeasurement& m, const Pose& T_lin, bool want_value);

}  // namespace mcms::internal
