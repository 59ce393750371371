// The inclinometer part of the model audit's fusion mode (issue 11, `mcms audit fusion`):
// the inclinometer's readings against the flange orientation another sensor measured (the
// tracker through the setup's registration and target mount), through the inclinometer's
// forward model (model/inclinometer.h, InclinometerReadingT of model/extensions.h) and
// its catalog extensions: inclinometer_bias (2), inclinometer_misalignment (3: the
// mounting rotation, flange frame), clock_offset and clock_drift (the inclinometer's
// stamps on the reference clock, ReferenceTimeT).
//
// Residuals. Each reading (stamp s_i) is predicted at its reference time t_i =
// ReferenceTimeT(s_i) (the clock extension; s_i without one) from the flange orientation
// interpolated between the two reference frames around it (R_a Exp(w Log(R_a^T R_b)),
// w = (t_i - t_a) / (t_b - t_a); with a dense motion record M(t), M(t) D(t) with the
// discrepancy D = M^T R interpolated so between the frames); residual = predicted - read. The readings between one
// pair of frames form a group whitened together: S = sigma^2 I + A C_a A^T + B C_b B^T
// (A, B: the tilts' Jacobians (Inclinometer::Tilt) times 1 - w_i and w_i), since they
// share the frames' errors. Only every other pair of frames is used, so that no frame is
// in two groups and the groups are independent; pairs further apart than 3 median frame
// periods (a lost frame) are not used, nor saturated readings. The readings of a group
// are fixed at the nominal clock (a clock extension moves them within or slightly beyond
// their pair: the interpolation extrapolates).
// The noise scale s (S -> s^2 S) is estimated with every model (profiled), so that a
// setup sigma that is off does not make an effect look significant; whether s = 1 is one
// of the residual tests.
//
// Procedure, with the engine of audit/model_selection.h: tests of the nominal residuals
// (chi-square against the setup's sigma, lag-1 autocorrelation, trends against time, both
// tilts and the tilt rates) at alpha / 2, then greedy forward selection over the catalog
// at alpha / 2 (k-fold held-out log-likelihood, folds = blocks of time); clock_drift
// extends a named clock_offset by its rate.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose_math.h"
#include "audit/audit_report.h"
#include "model/extensions.h"
#include "model/flange_pose.h"
#include "model/inclinometer.h"

namespace mcms {

// The flange's orientation measured by another sensor at a time on the reference clock.
struct OrientationReference {
  double time_s = 0.0;
  Mat3 R_base_flange = Mat3::Identity();
  Mat3 covariance = Mat3::Zero();  // dtheta, base frame (rad^2)
  int line = 0;
};

// The flange orientation the camera rig measured (model/flange_pose.h CameraFlangePose:
// the registration's and the target mount's transform, the registration's uncertainty
// added), at the tracker's time stamp.
OrientationReference CameraOrientationReference(const CellGeometry& cell, double time_s, const Pose& T_rig_target,
                                                const Mat6& covariance_rig, int line = 0);

struct InclinometerReadingSample {
  double time_s = 0.0;  // on the inclinometer's clock
  Vec2 reading = Vec2::Zero();
  int line = 0;
};

struct InclinometerAuditOptions {
  double false_alarm = 0.01;  // designed probability of calling a clean log not clean
  int folds = 5;
  int max_effects = 3;
  std::string name = "inclinometer";  // the sensor's name in the report (`where`)
  std::function<void(const std::string&)> progress;
  bool IsValid(std::string* why) const;
};

struct InclinometerAuditResult {
  AuditReport report;
  std::vector<Extension> extensions;            // the named effects, in order
  std::vector<std::vector<double>> parameters;  // per extension
  std::vector<std::vector<double>> sigmas;
  double noise_scale_nominal = 1.0, noise_scale = 1.0;  // estimated factor on the setup's noise
  // Per used reference frame: residuals (predicted - read, rad) of the nominal and the
  // extended model, and the covariates of the plots.
  struct Row {
    double time_s = 0.0;
    Vec2 tilt = Vec2::Zero();
    Vec2 nominal = Vec2::Zero(), extended = Vec2::Zero();
  };
  std::vector<Row> rows;
  // The inclinometer with the named bias and misalignment applied (clock effects are not
  // terms of the sensor: they are in the report).
  Inclinometer Extended(const Inclinometer& nominal) const;
};

// `motion` (optional, time order, on the reference clock): a dense record of the flange's
// orientation (e.g. the robot's forward kinematics at its joint log's stamps) whose shape
// interpolates between the reference frames, so that a frame rate far below the motion's
// curvature does not leave an interpolation error in the residuals; the reference frames
// still fix the orientation (the motion's own error is interpolated linearly between them).
struct OrientationSample {
  double time_s = 0.0;
  Mat3 R_base_flange = Mat3::Identity();
};
InclinometerAuditResult AuditInclinometer(const Inclinometer& incl, const std::vector<OrientationReference>& reference,
                                          const std::vector<InclinometerReadingSample>& readings,
                                          const InclinometerAuditOptions& options = {},
                                          const std::vector<OrientationSample>& motion = {});

// Writes `prefix`residuals.csv and plots/`prefix`residuals_vs_time.svg,
// plots/`prefix`residuals_vs_tilt.svg into dir (which must exist).
void WriteInclinometerAuditFiles(const InclinometerAuditResult& r, const std::filesystem::path& dir,
                                 const std::string& prefix = "inclinometer_");

// ---- the cost of one group of readings (exposed for the gradient check) -----------
// Whitened predicted-minus-read residuals (2 per reading) of the readings between two
// reference frames; p[k] is the block of ext[k] (inclinometer_bias,
// inclinometer_misalignment, clock_offset or clock_drift, each at most once).
struct InclinometerGroupCost {
  const Inclinometer* incl = nullptr;
  const std::vector<Extension>* ext = nullptr;
  double t0 = 0.0;  // clock_drift's origin (inclinometer clock)
  double t_a = 0.0, t_b = 1.0;  // the two reference frames' times
  // R(t) = M(t) D_a Exp(w chi), w = (t - t_a) / (t_b - t_a): the reference frames'
  // orientations are M(t_a) D_a and M(t_b) D_a Exp(chi); M is the motion's shape (the
  // identity without one).
  Mat3 D_a = Mat3::Identity();
  Vec3 chi = Vec3::Zero();
  std::vector<double> s;  // the readings' stamps
  std::vector<Vec2> z;    // and values
  // Per reading: the motion's segment around its reference time, M(t) = M0 Exp(u psi),
  // u = (t - m_t0) / (m_t1 - m_t0); empty: no motion (M = I).
  std::vector<double> m_t0, m_t1;
  std::vector<Mat3> m_R0;
  std::vector<Vec3> m_psi;
  Eigen::MatrixXd whitening;  // 2n x 2n

  int NumResiduals() const { return 2 * static_cast<int>(s.size()); }

  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    const T* bias = nullptr;
    const T* mis = nullptr;
    const T* pc = nullptr;
    const Extension* clock = nullptr;
    for (size_t k = 0; k < ext->size(); ++k) {
      const Extension& e = (*ext)[k];
      if (e.effect == Effect::kInclinometerBias) bias = p[k];
      else if (e.effect == Effect::kInclinometerMisalignment) mis = p[k];
      else if (e.effect == Effect::kClockOffset || e.effect == Effect::kClockDrift) clock = &e, pc = p[k];
    }
    using M3 = Eigen::Matrix<T, 3, 3>;
    const int n = static_cast<int>(s.size());
    Eigen::Matrix<T, Eigen::Dynamic, 1> e(2 * n);
    for (int i = 0; i < n; ++i) {
      const T t = clock ? ReferenceTimeT<T>(*clock, pc, s[i], t0) : T(s[i]);
      const T w = (t - T(t_a)) / T(t_b - t_a);
      const T aa[3] = {w * chi[0], w * chi[1], w * chi[2]};
      M3 E;
      ceres::AngleAxisToRotationMatrix(aa, E.data());
      M3 R = D_a.cast<T>() * E;
      if (!m_R0.empty()) {
        const T u = (t - T(m_t0[i])) / T(m_t1[i] - m_t0[i]);
        const T bb[3] = {u * m_psi[i][0], u * m_psi[i][1], u * m_psi[i][2]};
        M3 F;
        ceres::AngleAxisToRotationMatrix(bb, F.data());
        R = m_R0[i].cast<T>() * F * R;
      }
      const Eigen::Matrix<T, 2, 1> pred =
          InclinometerReadingOfT<T>(R, incl->R_flange_incl, mis, bias) + incl->bias.cast<T>();
      e[2 * i] = pred[0] - T(z[i][0]);
      e[2 * i + 1] = pred[1] - T(z[i][1]);
    }
    for (int a = 0; a < 2 * n; ++a) {
      T acc(0.0);
      for (int b = 0; b <= a; ++b) acc += whitening(a, b) * e[b];  // lower triangular
      r[a] = acc;
    }
    return true;
  }
};

}  // namespace mcms
