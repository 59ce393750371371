// The paper's lab experiment (section 3.4) with the camera the measured repeatability
// describes (issue 12): the forward model's lab scenario (synthetic/lab_scenario.h) and
// its fusion (jobs/lab_experiment.h), with the tracker's poses replaced by the truth
// plus the error of a camera model, nominal or fitted (audit/repeatability.h).
//
// Camera models. Nominal: the predicted pose covariance of the rig at the lab's sphere
// centre, drawn independently per frame (what the rendered demo's tracker achieves).
// Fitted: the camera error model (synthetic/camera_error_model.h, the one definition the
// rendered demo `mcms demo --camera-model` also uses): per frame, the nominal pose
// covariance times the pixel-noise scale^2; per visit (dwell), one rigid translation error
// (floor and anisotropy, rig axes) shared by its frames. Each frame reports the pixel
// covariance plus the visit covariance times the dwell's frame count, so that the dwell's
// frames fused as independent report the visit covariance. Misidentified points are left
// out (the paper used the points of its effective field of view).
#pragma once

#include <string>
#include <vector>

#include "core/pose_math.h"
#include "synthetic/camera_error_model.h"
#include "audit/repeatability.h"

namespace mcms {

// LabReductionResult (audit/repeatability.h): three-sigma-rule position errors
// (mean + 3 std of |dp|, m), mean over the seeds, and the reductions of MOIFA and KF
// relative to the camera (1 - fused / camera), mean and sd over the seeds.
using LabReduction = LabReductionResult;

// nominal_cov: the rig's predicted 6x6 pose covariance at the lab sphere's centre
// ([dtheta; dp], rig frame). `seeds` repetitions of the camera errors (the lab scenario
// itself is the default one). Rows: nominal camera, fitted camera (forward-model robot),
// and, when paper_robot_3sigma_m > 0, the fitted camera with the robot's DH errors scaled
// until its three-sigma position error is the paper's (Table 4: 3.379 mm).
std::vector<LabReduction> PredictLabReductions(const CameraErrorModel& model, const Mat6& nominal_cov, int seeds = 5,
                                               int points = 76, double paper_robot_3sigma_m = 3.379e-3);

}  // namespace mcms
