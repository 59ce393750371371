// Kalman filters for the multi-sensor combined measuring system.
//
// (a) The paper's scheme (section 2.2.1): one Kalman filter per sensor on a 3-D position
//     with a random-walk model (eqs. 1-5 with A = B = C = I), followed by the weighted
//     fusion of the per-sensor estimates (eq. 14, with the corrected weights of
//     fusion/moifa.h). RandomWalkKalmanFilter and PerSensorKalmanFusion.
// (b) One multi-sensor filter over the full pose with a constant-velocity motion model,
//     taking each sensor at its own rate and time stamp, and predicting ahead for
//     real-time compensation. PoseKalmanFilter.
//
// What (a) does and does not do. With process noise Q -> 0 the per-sensor filter believes
// the state never moves, so its estimate after k steps is the average of k measurements
// and its error shrinks as 1/sqrt(k): the "improvement" comes from averaging over time, not
// from combining sensors. With Q matched to a state that really moves (Q >> R between
// independent points) its gain tends to 1 and each filter returns its latest measurement,
// so (a) reduces to MOIFA. fusion/paper_simulation.h quantifies both for section 3.3.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "model/inclinometer.h"
#include "model/robot_model.h"
#include "core/pose_math.h"
#include "fusion/moifa.h"

namespace mcms {

// The paper's per-sensor filter, eqs. (1)-(5) with A = B = C = I:
//   x(k) = x(k-1) + u(k) + w(k),  w ~ N(0, Q)     (random walk; u a known displacement)
//   y(k) = x(k) + v(k),           v ~ N(0, R)
class RandomWalkKalmanFilter {
 public:
  bool Initialized() const { return initialized_; }
  // x0 finite, P0 symmetric positive definite; InputError otherwise.
  void Initialize(const Vec3& x0, const Mat3& P0);
  // Eqs. (2) and (4): x <- x + u, P <- P + Q (Q symmetric positive semi-definite, m^2).
  void Predict(const Mat3& Q, const Vec3& u = Vec3::Zero());
  // Eqs. (3), (1), (5) (the covariance in Joseph form). Returns the NIS of y against the
  // prediction, chi-square with 3 dof when the model holds. InputError if not initialized.
  double Update(const Vec3& y, const Mat3& R);
  const Vec3& State() const { return x_; }
  const Mat3& Covariance() const { return P_; }

 private:
  bool initialized_ = false;
  Vec3 x_ = Vec3::Zero();
  Mat3 P_ = Mat3::Zero();
};

// The paper's KF fusion: one RandomWalkKalmanFilter per sensor, all with the same process
// noise per step, then eq. (14) with MOIFA weights from the filters' covariances.
// Contract: the fusion treats the filters' errors as independent. That holds for Q = 0;
// with Q > 0 all filters share the state's process noise, their errors are correlated and
// the fused covariance is optimistic. PoseKalmanFilter (one filter, all sensors) has no
// such approximation.
class PerSensorKalmanFusion {
 public:
  // InputError when num_sensors < 1 or Q is not symmetric positive semi-definite.
  PerSensorKalmanFusion(int num_sensors, const Mat3& process_noise_per_step);

  struct Result {
    FusedPosition fused;               // eq. 14 of the filtered estimates
    std::vector<double> nis;           // per sensor; NaN on each filter's first step
  };
  // One step: y[i] with covariance R[i] for every sensor, u the known displacement of the
  // state since the previous step (zero in the paper). On the first step each filter starts
  // from its measurement (x = y, P = R: the limit of a diffuse prior).
  Result Step(const std::vector<Vec3>& y, const std::vector<Mat3>& R, const Vec3& u = Vec3::Zero());
  const RandomWalkKalmanFilter& Filter(int i) const { return filters_.at(i); }
  int NumSensors() const { return static_cast<int>(filters_.size()); }

 private:
  std::vector<RandomWalkKalmanFilter> filters_;
  Mat3 Q_;
};

struct PoseKalmanOptions {
  // Spectral densities of the white accelerations that drive the constant-velocity model:
  // angular acceleration in rad^2/s^3 (base frame), linear in m^2/s^3. Over a time dt the
  // velocity wanders by sqrt(psd * dt) (1 sigma): 1e-2 m^2/s^3 lets a slow robot change its
  // speed by 0.1 m/s in one second. Larger values follow sharper motion and smooth less.
  double angular_acceleration_psd = 1e-2;
  double linear_acceleration_psd = 1e-2;
  // Prior standard deviation of the velocities at Initialize.
  double initial_angular_velocity_sigma = 0.5;  // rad/s
  double initial_linear_velocity_sigma = 0.5;   // m/s
  // Reject an update whose NIS exceeds the chi-square quantile of this probability for its
  // dof (e.g. 0.999); 0 accepts every update.
  double nis_gate_probability = 0.0;
  bool IsValid(std::string* why = nullptr) const;
};

// One multi-sensor error-state filter over the pose of one body (e.g. the flange) in the
// base frame, with a constant-velocity model.
//   Nominal state: T = (R, p), angular velocity w and linear velocity v, both in the base
//   frame; R(t+dt) = Exp(w dt) R(t), p(t+dt) = p(t) + v dt.
//   Error state (12): [dtheta; dp; dw; dv] with R = Exp(dtheta) R_hat, p = p_hat + dp
//   (docs/conventions.md), so the top-left 6x6 of the covariance is the project's pose
//   covariance.
// Sensors arrive at their own rates: every update carries its time stamp t; the filter
// propagates to t first. Time stamps must not decrease (InputError), equal ones are fine.
class PoseKalmanFilter {
 public:
  // InputError when options are invalid.
  explicit PoseKalmanFilter(const PoseKalmanOptions& options = {});

  // Starts the filter at time t with pose T (6x6 covariance in [dtheta; dp]) and velocities
  // w, v whose prior sigmas come from the options.
  void Initialize(double t, const Pose& T, const Mat6& covariance, const Vec3& w = Vec3::Zero(),
                  const Vec3& v = Vec3::Zero());
  bool Initialized() const { return initialized_; }
  double Time() const { return t_; }

  struct UpdateResult {
    double nis = 0.0;      // normalized innovation squared of this update
    int dof = 0;           // its degrees of freedom (chi-square when the filter is consistent)
    bool accepted = true;  // false when rejected by the NIS gate
  };
  // A full pose measurement (camera frame, robot FK) with 6x6 covariance in [dtheta; dp].
  UpdateResult UpdatePose(double t, const Pose& T_measured, const Mat6& covariance);
  // A possibly partial measurement in information form (its rank is the dof).
  UpdateResult UpdateInformation(double t, const PoseMeasurement& measurement);
  // An inclinometer reading, linearized at the predicted orientation: its rank-2
  // information (Inclinometer::Constraint) through UpdateInformation. The filter's body
  // must be the flange the inclinometer sits on.
  UpdateResult UpdateInclinometer(double t, const Vec2& reading, const Inclinometer& inclinometer);
  // The robot's own pose at controller rate: FK of the encoder readings q at the robot's
  // tool frame, covariance J Q_enc J^T + model_covariance (the encoders say nothing of the
  // robot's absolute accuracy; model_covariance carries it, e.g. the paper's
  // 0.157/0.087/0.043 mm). The tool frame must be the filter's body.
  UpdateResult UpdateRobot(double t, const RobotModel& robot, const Eigen::VectorXd& q,
                           const Mat6& model_covariance);

  // Moves the state to time t without a measurement (t >= Time()).
  void PropagateTo(double t);

  struct Prediction {
    Pose T;
    Mat6 covariance = Mat6::Zero();  // [dtheta; dp]
    Vec3 w = Vec3::Zero(), v = Vec3::Zero();
  };
  // The state extrapolated to t >= Time() (e.g. now + controller latency), without changing
  // the filter.
  Prediction Predict(double t) const;

  const Pose& PoseEstimate() const { return T_; }
  Mat6 PoseCovariance() const { return P_.topLeftCorner<6, 6>(); }
  const Vec3& AngularVelocity() const { return w_; }
  const Vec3& LinearVelocity() const { return v_; }
  const Eigen::Matrix<double, 12, 12>& Covariance() const { return P_; }
  const PoseKalmanOptions& Options() const { return options_; }

 private:
  void CheckTime(double t, const char* what) const;
  // Constant-velocity propagation of (T, w, v, P) by dt >= 0.
  static void Propagate(const PoseKalmanOptions& o, double dt, Pose* T, Vec3* w, Vec3* v,
                        Eigen::Matrix<double, 12, 12>* P);
  // Kalman correction with a measurement z = H_pose x_pose + n on the pose part of the
  // error state (H_pose is m x 6), n ~ N(0, Rn).
  UpdateResult Correct(const Eigen::MatrixXd& H_pose, const Eigen::VectorXd& innovation, const Eigen::MatrixXd& Rn);

  PoseKalmanOptions options_;
  bool initialized_ = false;
  double t_ = 0.0;
  Pose T_;
  Vec3 w_ = Vec3::Zero(), v_ = Vec3::Zero();
  Eigen::Matrix<double, 12, 12> P_ = Eigen::Matrix<double, 12, 12>::Zero();
  double gate_[7] = {0, 0, 0, 0, 0, 0, 0};  // chi-square gate per dof 1..6
};

}  // namespace mcms
