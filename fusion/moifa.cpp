#include "fusion/moifa.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "core/error.h"
#include "fusion/gaussian_internal.h"
#include "fusion/moifa_internal.h"

namespace mcms {

using internal::CovarianceToInformation;
using internal::SolveTotalInformation;
using internal::ValidateInformation;

namespace {
std::string Who(const std::string& kind, const std::string& name) {
  return kind + " measurement '" + (name.empty() ? std::string("(unnamed)") : name) + "'";
}
}  // namespace

PositionMeasurement PositionMeasurement::FromCovariance(std::string name, const Vec3& p, const Mat3& covariance) {
  const std::string who = Who("position", name);
  if (!p.allFinite()) Throw(who, ": position is not finite");
  PositionMeasurement m;
  m.information = CovarianceToInformation<3>(covariance, who);
  m.information_vector = m.information * p;
  m.name = std::move(name);
  return m;
}

PositionMeasurement PositionMeasurement::FromInformation(std::string name, const Mat3& information,
                                                         const Vec3& information_vector) {
  ValidateInformation<3>(information, information_vector, Who("position", name));
  PositionMeasurement m;
  m.information = 0.5 * (information + information.transpose());
  m.information_vector = information_vector;
  m.name = std::move(name);
  return m;
}

FusedPosition FusePositions(const std::vector<PositionMeasurement>& measurements) {
  if (measurements.empty()) Throw("cannot fuse positions: no measurement given");
  Mat3 H = Mat3::Zero();
  Vec3 g = Vec3::Zero();
  for (const auto& m : measurements) {
    H += m.information;
    g += m.information_vector;
  }
  FusedPosition f;
  SolveTotalInformation<3>(H, g, "positions", &f.covariance, &f.p);
  f.weights.reserve(measurements.size());
  for (const auto& m : measurements) f.weights.push_back(f.covariance * m.information);
  return f;
}

std::vector<Mat3> PrintedEquation13Weights(const std::vector<Mat3>& covariances) {
  if (covariances.empty()) Throw("eq. 13 weights: no covariance given");
  Mat3 sum = Mat3::Zero();
  for (const Mat3& P : covariances) sum += P;
  const Mat3 sum_inv = sum.inverse();
  std::vector<Mat3> W;
  for (size_t i = 0; i < covariances.size(); ++i)
    W.push_back(sum_inv * CovarianceToInformation<3>(covariances[i], "eq. 13 covariance " + std::to_string(i)));
  return W;
}

PoseMeasurement PoseMeasurement::FromCovariance(std::string name, const Pose& T, const Mat6& covariance) {
  const std::string who = Who("pose", name);
  if (!T.R.allFinite() || !T.t.allFinite() || (T.R.transpose() * T.R - Mat3::Identity()).norm() > 1e-6)
    Throw(who, ": pose is not a finite rigid transform");
  PoseMeasurement m;
  m.T_ref = T;
  m.information = CovarianceToInformation<6>(covariance, who);
  m.name = std::move(name);
  return m;
}

PoseMeasurement PoseMeasurement::FromInformation(std::string name, const Pose& T_ref, const Mat6& information,
                                                 const Vec6& information_vector) {
  const std::string who = Who("pose", name);
  if (!T_ref.R.allFinite() || !T_ref.t.allFinite() || (T_ref.R.transpose() * T_ref.R - Mat3::Identity()).norm() > 1e-6)
    Throw(who, ": linearization pose is not a finite rigid transform");
  ValidateInformation<6>(information, information_vector, who);
  PoseMeasurement m;
  m.T_ref = T_ref;
  m.information = 0.5 * (information + information.transpose());
  m.information_vector = information_vector;
  m.name = std::move(name);
  return m;
}

PoseMeasurement PoseMeasurement::FromOrientation(std::string name, const OrientationInformation& o) {
  Mat6 L = Mat6::Zero();
  L.topLeftCorner<3, 3>() = o.information;
  Vec6 eta = Vec6::Zero();
  eta.head<3>() = o.information_vector;
  return FromInformation(std::move(name), Pose{o.R_base_flange_lin, Vec3::Zero()}, L, eta);
}

bool FusePosesOptions::IsValid(std::string* why) const {
  std::ostringstream s;
  if (iterations < 1 || iterations > 100) s << "iterations must be in 1..100, is " << iterations;
  if (linearization_index < -1) s << "linearization_index must be -1 (automatic) or a measurement index";
  if (s.tellp() == 0) return true;
  if (why) *why = "pose fusion options: " + s.str();
  return false;
}

namespace internal {

LinearizedPose Linearize(const PoseMeasurement& m, const Pose& T_lin, bool want_value) {
  const Vec6 delta = BoxMinus(T_lin, m.T_ref);
  const Mat3 Jl = LeftJacobianSO3(delta.head<3>());
  // A = diag(Jl^-1, I): x_m = delta + A x. Work with A^-1 = diag(Jl, I) where possible.
  const Mat3 Jl_inv = Jl.inverse();
  LinearizedPose out;
  const Mat6& L = m.information;
  // A^T L A with A block-diagonal.
  out.information.topLeftCorner<3, 3>() = Jl_inv.transpose() * L.topLeftCorner<3, 3>() * Jl_inv;
  out.information.topRightCorner<3, 3>() = Jl_inv.transpose() * L.topRightCorner<3, 3>();
  out.information.bottomLeftCorner<3, 3>() = out.information.topRightCorner<3, 3>().transpose();
  out.information.bottomRightCorner<3, 3>() = L.bottomRightCorner<3, 3>();
  const Vec6 r = m.information_vector - L * delta;
  out.information_vector.head<3>() = Jl_inv.transpose() * r.head<3>();
  out.information_vector.tail<3>() = r.tail<3>();
  if (want_value) {
    // b = A^-1 (x_m* - delta), x_m* = L^+ eta the measurement's own minimizer.
    const Vec6 own = m.information_vector.isZero(0.0) ? Vec6::Zero() : Vec6(PseudoInverse<6>(L) * m.information_vector);
    const Vec6 d = own - delta;
    out.value.head<3>() = Jl * d.head<3>();
    out.value.tail<3>() = d.tail<3>();
  }
  return out;
}

}  // namespace internal

FusedPose FusePoses(const std::vector<PoseMeasurement>& measurements, const FusePosesOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw(why);
  if (measurements.empty()) Throw("cannot fuse poses: no measurement given");
  const int n = static_cast<int>(measurements.size());
  int lin = options.linearization_index;
  if (lin >= n) Throw("pose fusion options: linearization_index ", lin, " but only ", n, " measurements");
  if (lin < 0) {
    // The most precise full-rank estimate: its own T_ref is then already within its
    // (small) error of the answer, which keeps the first linearization error tiny.
    double best = -std::numeric_limits<double>::infinity();
    lin = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::LLT<Mat6> llt(measurements[i].information);
      if (llt.info() != Eigen::Success) continue;
      const Mat6 Lc = llt.matrixL();
      const double logdet = 2.0 * Lc.diagonal().array().log().sum();
      if (std::isfinite(logdet) && logdet > best) {
        best = logdet;
        lin = i;
      }
    }
  }
  FusedPose f;
  f.T = measurements[lin].T_ref;
  Mat6 H;
  Vec6 g, x;
  // iterations Gauss-Newton steps, then one more linearization at the result for the
  // covariance and weights (its step, ~1e-12, is applied too).
  for (int it = 0; it <= options.iterations; ++it) {
    H.setZero();
    g.setZero();
    if (it == options.iterations) f.weights.clear();
    for (const auto& m : measurements) {
      const internal::LinearizedPose lp = internal::Linearize(m, f.T, false);
      H += lp.information;
      g += lp.information_vector;
      if (it == options.iterations) f.weights.push_back(lp.information);
    }
    SolveTotalInformation<6>(H, g, "poses", &f.covariance, &x);
    f.T = BoxPlus(f.T, x);
  }
  for (Mat6& W : f.weights) W = f.covariance * W;
  return f;
}

}  // namespace mcms
