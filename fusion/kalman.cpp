#include "fusion/kalman.h"

#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/error.h"
#include "core/statistics.h"
#include "fusion/gaussian_internal.h"
#include "fusion/moifa_internal.h"

namespace mcms {

namespace {

void CheckPsd3(const Mat3& Q, const char* who) {
  if (!Q.allFinite() || !internal::IsSymmetric<3>(Q)) Throw(who, " must be finite and symmetric");
  const double lo = Eigen::SelfAdjointEigenSolver<Mat3>(Q, Eigen::EigenvaluesOnly).eigenvalues()[0];
  if (lo < -1e-12 * Q.cwiseAbs().maxCoeff()) Throw(who, " must be positive semi-definite");
}

}  // namespace

// ---------------------------------------------------------------------------------------
// (a) The paper's per-sensor filters.

void RandomWalkKalmanFilter::Initialize(const Vec3& x0, const Mat3& P0) {
  if (!x0.allFinite()) Throw("Kalman filter: initial state is not finite");
  internal::CovarianceToInformation<3>(P0, "Kalman filter initial covariance");  // checks SPD
  x_ = x0;
  P_ = 0.5 * (P0 + P0.transpose());
  initialized_ = true;
}

void RandomWalkKalmanFilter::Predict(const Mat3& Q, const Vec3& u) {
  if (!initialized_) Throw("Kalman filter: Predict before Initialize");
  CheckPsd3(Q, "Kalman filter process noise Q");
  if (!u.allFinite()) Throw("Kalman filter: displacement u is not finite");
  x_ += u;     // eq. (2), A = I (plus the known displacement)
  P_ += Q;     // eq. (4), A = B = I
}

double RandomWalkKalmanFilter::Update(const Vec3& y, const Mat3& R) {
  if (!initialized_) Throw("Kalman filter: Update before Initialize");
  if (!y.allFinite()) Throw("Kalman filter: measurement is not finite");
  CheckPsd3(R, "Kalman filter measurement noise R");
  const Mat3 S = P_ + R;
  const Eigen::LLT<Mat3> llt(S);
  if (llt.info() != Eigen::Success) Throw("Kalman filter: innovation covariance is singular");
  const Vec3 nu = y - x_;
  const Mat3 K = llt.solve(P_).transpose();  // eq. (3): P S^-1 (P, S symmetric)
  x_ += K * nu;                              // eq. (1)
  const Mat3 IK = Mat3::Identity() - K;
  P_ = IK * P_ * IK.transpose() + K * R * K.transpose();  // eq. (5) in Joseph form
  P_ = 0.5 * (P_ + P_.transpose());
  return nu.dot(llt.solve(nu));
}

namespace {
const char* const kFilterName = "per-sensor Kalman estimate";
}  // namespace

PerSensorKalmanFusion::PerSensorKalmanFusion(int num_sensors, const Mat3& process_noise_per_step)
    : filters_(num_sensors > 0 ? num_sensors : 0), Q_(process_noise_per_step) {
  if (num_sensors < 1) Throw("per-sensor Kalman fusion: needs at least one sensor, got ", num_sensors);
  CheckPsd3(Q_, "per-sensor Kalman fusion process noise");
}

PerSensorKalmanFusion::Result PerSensorKalmanFusion::Step(const std::vector<Vec3>& y, const std::vector<Mat3>& R,
                                                          const Vec3& u) {
  if (y.size() != filters_.size() || R.size() != filters_.size())
    Throw("per-sensor Kalman fusion: expected ", filters_.size(), " measurements and covariances, got ", y.size(),
          " and ", R.size());
  Result r;
  std::vector<PositionMeasurement> estimates;
  for (size_t i = 0; i < filters_.size(); ++i) {
    RandomWalkKalmanFilter& f = filters_[i];
    if (!f.Initialized()) {
      f.Initialize(y[i], R[i]);
      r.nis.push_back(std::numeric_limits<double>::quiet_NaN());
    } else {
      f.Predict(Q_, u);
      r.nis.push_back(f.Update(y[i], R[i]));
    }
    estimates.push_back(PositionMeasurement::FromCovariance(kFilterName, f.State(), f.Covariance()));
  }
  r.fused = FusePositions(estimates);  // eq. (14)
  return r;
}

// ---------------------------------------------------------------------------------------
// (b) The multi-sensor pose filter.

namespace {
constexpr double kMaxKalmanPsd = 1e6;  // rad^2/s^3 or m^2/s^3, and (rad or m)/s for the sigmas
}  // namespace

bool PoseKalmanOptions::IsValid(std::string* why) const {
  std::ostringstream s;
  // Positive, and below what any pose process holds: the state covariance grows as the PSD
  // times dt^3, and beyond this it overflows the filter's arithmetic (kMaxKalmanPsd).
  const auto positive = [&](double v, const char* name) {
    if (!(v > 0) || !(v <= kMaxKalmanPsd))
      s << (s.tellp() ? "; " : "") << name << " must be positive and at most " << kMaxKalmanPsd << ", is " << v;
  };
  positive(angular_acceleration_psd, "angular_acceleration_psd");
  positive(linear_acceleration_psd, "linear_acceleration_psd");
  positive(initial_angular_velocity_sigma, "initial_angular_velocity_sigma");
  positive(initial_linear_velocity_sigma, "initial_linear_velocity_sigma");
  if (!(nis_gate_probability >= 0.0 && nis_gate_probability < 1.0))
    s << (s.tellp() ? "; " : "") << "nis_gate_probability must be in [0, 1), is " << nis_gate_probability;
  if (s.tellp() == 0) return true;
  if (why) *why = "pose Kalman filter options: " + s.str();
  return false;
}

PoseKalmanFilter::PoseKalmanFilter(const PoseKalmanOptions& options) : options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) Throw(why);
  if (options_.nis_gate_probability > 0)
    for (int dof = 1; dof <= 6; ++dof) gate_[dof] = ChiSquareQuantile(options_.nis_gate_probability, dof);
}

void PoseKalmanFilter::Initialize(double t, const Pose& T, const Mat6& covariance, const Vec3& w, const Vec3& v) {
  if (!std::isfinite(t)) Throw("pose Kalman filter: initial time is not finite");
  internal::CovarianceToInformation<6>(covariance, "pose Kalman filter initial covariance");  // checks SPD
  if (!T.R.allFinite() || !T.t.allFinite() || !w.allFinite() || !v.allFinite())
    Throw("pose Kalman filter: initial state is not finite");
  t_ = t;
  T_ = T;
  w_ = w;
  v_ = v;
  P_.setZero();
  P_.topLeftCorner<6, 6>() = 0.5 * (covariance + covariance.transpose());
  P_.block<3, 3>(6, 6) = std::pow(options_.initial_angular_velocity_sigma, 2) * Mat3::Identity();
  P_.block<3, 3>(9, 9) = std::pow(options_.initial_linear_velocity_sigma, 2) * Mat3::Identity();
  initialized_ = true;
}

void PoseKalmanFilter::CheckTime(double t, const char* what) const {
  if (!initialized_) Throw("pose Kalman filter: ", what, " before Initialize");
  if (!std::isfinite(t)) Throw("pose Kalman filter: ", what, " time stamp is not finite");
  if (t < t_) {
    std::ostringstream s;
    s.precision(9);
    s << std::fixed << "pose Kalman filter: " << what << " time stamp " << t << " s is earlier than the filter time "
      << t_ << " s; measurements must arrive in time order (buffer and sort them, or drop late ones)";
    Throw(s.str());
  }
}

void PoseKalmanFilter::Propagate(const PoseKalmanOptions& o, double dt, Pose* T, Vec3* w, Vec3* v,
                                 Eigen::Matrix<double, 12, 12>* P) {
  if (dt <= 0) return;
  const Vec3 phi = *w * dt;
  const Mat3 dR = ExpSO3(phi);
  // Error dynamics: R' = Exp((w_hat + dw) dt) Exp(dtheta) R_hat
  //   => dtheta' = Exp(w_hat dt) dtheta + J_l(w_hat dt) dt dw,  dp' = dp + dt dv.
  Eigen::Matrix<double, 12, 12> F = Eigen::Matrix<double, 12, 12>::Identity();
  F.block<3, 3>(0, 0) = dR;
  F.block<3, 3>(0, 6) = LeftJacobianSO3(phi) * dt;
  F.block<3, 3>(3, 9) = Mat3::Identity() * dt;
  // Integrated white acceleration, per axis [dt^3/3, dt^2/2; dt^2/2, dt] * psd.
  Eigen::Matrix<double, 12, 12> Q = Eigen::Matrix<double, 12, 12>::Zero();
  const double dt2 = dt * dt, dt3 = dt2 * dt;
  for (int k = 0; k < 2; ++k) {
    const double q = k == 0 ? o.angular_acceleration_psd : o.linear_acceleration_psd;
    const int a = 3 * k, b = 6 + 3 * k;  // (dtheta, dw) then (dp, dv)
    Q.block<3, 3>(a, a) = q * dt3 / 3.0 * Mat3::Identity();
    Q.block<3, 3>(a, b) = q * dt2 / 2.0 * Mat3::Identity();
    Q.block<3, 3>(b, a) = q * dt2 / 2.0 * Mat3::Identity();
    Q.block<3, 3>(b, b) = q * dt * Mat3::Identity();
  }
  *P = F * *P * F.transpose() + Q;
  *P = 0.5 * (*P + P->transpose());
  T->R = dR * T->R;
  T->t += *v * dt;
}

void PoseKalmanFilter::PropagateTo(double t) {
  CheckTime(t, "propagation");
  Propagate(options_, t - t_, &T_, &w_, &v_, &P_);
  t_ = t;
}

PoseKalmanFilter::Prediction PoseKalmanFilter::Predict(double t) const {
  CheckTime(t, "prediction");
  Prediction p;
  p.T = T_;
  p.w = w_;
  p.v = v_;
  Eigen::Matrix<double, 12, 12> P = P_;
  Propagate(options_, t - t_, &p.T, &p.w, &p.v, &P);
  p.covariance = P.topLeftCorner<6, 6>();
  return p;
}

PoseKalmanFilter::UpdateResult PoseKalmanFilter::Correct(const Eigen::MatrixXd& H_pose,
                                                         const Eigen::VectorXd& innovation,
                                                         const Eigen::MatrixXd& Rn) {
  const int m = static_cast<int>(innovation.size());
  // H = [H_pose 0]: only the pose part of the error state is observed.
  const Eigen::MatrixXd PHt = P_.leftCols<6>() * H_pose.transpose();  // 12 x m
  Eigen::MatrixXd S = H_pose * PHt.topRows<6>() + Rn;
  S = 0.5 * (S + S.transpose());
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  if (llt.info() != Eigen::Success) Throw("pose Kalman filter: innovation covariance is not positive definite");
  UpdateResult r;
  r.dof = m;
  r.nis = innovation.dot(llt.solve(innovation));
  if (options_.nis_gate_probability > 0 && m >= 1 && m <= 6 && r.nis > gate_[m]) {
    r.accepted = false;
    return r;
  }
  const Eigen::MatrixXd K = llt.solve(PHt.transpose()).transpose();  // 12 x m
  const Eigen::Matrix<double, 12, 1> dx = K * innovation;
  Eigen::Matrix<double, 12, 12> IKH = Eigen::Matrix<double, 12, 12>::Identity();
  IKH.leftCols<6>() -= K * H_pose;
  P_ = IKH * P_ * IKH.transpose() + K * Rn * K.transpose();  // Joseph form
  P_ = 0.5 * (P_ + P_.transpose());
  // Inject the error estimate into the nominal state (the reset's rotation Jacobian is
  // I + O(|dtheta|) and is neglected, as the corrections are sub-milliradian).
  T_ = BoxPlus(T_, dx.head<6>());
  w_ += dx.segment<3>(6);
  v_ += dx.tail<3>();
  return r;
}

PoseKalmanFilter::UpdateResult PoseKalmanFilter::UpdatePose(double t, const Pose& T_measured, const Mat6& covariance) {
  CheckTime(t, "pose update");
  if (!T_measured.R.allFinite() || !T_measured.t.allFinite()) Throw("pose Kalman filter: measured pose is not finite");
  if (!covariance.allFinite() || !internal::IsSymmetric<6>(covariance) ||
      Eigen::LLT<Mat6>(covariance).info() != Eigen::Success)
    Throw("pose Kalman filter: pose covariance must be symmetric positive definite");
  PropagateTo(t);
  // Innovation on the tangent at the prediction: b = BoxMinus(T_measured, T_hat). With
  // delta = BoxMinus(T_hat, T_measured) = -b and x_m = delta + diag(J_l(delta)^-1, I) x
  // (moifa_internal.h), the measurement of x is b with covariance A C A^T,
  // A = diag(J_l(delta), I).
  const Vec6 b = BoxMinus(T_measured, T_);
  Mat6 A = Mat6::Identity();
  A.topLeftCorner<3, 3>() = LeftJacobianSO3(-b.head<3>());
  const Mat6 C = A * covariance * A.transpose();
  return Correct(Eigen::MatrixXd::Identity(6, 6), b, 0.5 * (C + C.transpose()));
}

PoseKalmanFilter::UpdateResult PoseKalmanFilter::UpdateInformation(double t, const PoseMeasurement& measurement) {
  CheckTime(t, "information update");
  PropagateTo(t);
  const internal::LinearizedPose lp = internal::Linearize(measurement, T_, true);
  // L = U D U^T over its range: the equivalent measurement z = U^T x + n, n ~ N(0, D^-1),
  // with z = U^T b.
  const Eigen::SelfAdjointEigenSolver<Mat6> es(0.5 * (lp.information + lp.information.transpose()));
  const double hi = es.eigenvalues().cwiseAbs().maxCoeff();
  std::vector<int> keep;
  for (int i = 0; i < 6; ++i)
    if (hi > 0 && es.eigenvalues()[i] > internal::kRelativeRankTolerance * hi) keep.push_back(i);
  if (keep.empty()) Throw("pose Kalman filter: measurement '", measurement.name, "' carries no information");
  const int m = static_cast<int>(keep.size());
  Eigen::MatrixXd U(6, m);
  Eigen::MatrixXd Rn = Eigen::MatrixXd::Zero(m, m);
  for (int k = 0; k < m; ++k) {
    U.col(k) = es.eigenvectors().col(keep[k]);
    Rn(k, k) = 1.0 / es.eigenvalues()[keep[k]];
  }
  const Eigen::VectorXd z = U.transpose() * lp.value;
  return Correct(U.transpose(), z, Rn);
}

PoseKalmanFilter::UpdateResult PoseKalmanFilter::UpdateInclinometer(double t, const Vec2& reading,
                                                                    const Inclinometer& inclinometer) {
  CheckTime(t, "inclinometer update");
  PropagateTo(t);
  const OrientationInformation c = inclinometer.Constraint(reading, T_.R);
  return UpdateInformation(t, PoseMeasurement::FromOrientation("inclinometer", c));
}

PoseKalmanFilter::UpdateResult PoseKalmanFilter::UpdateRobot(double t, const RobotModel& robot,
                                                             const Eigen::VectorXd& q, const Mat6& model_covariance) {
  CheckTime(t, "robot update");
  const Pose T = robot.T_base_tool(q);
  const Mat6 C = robot.PoseCovariance(q, RobotModel::EndFrame::kTool) + model_covariance;
  return UpdatePose(t, T, C);
}

}  // namespace mcms
