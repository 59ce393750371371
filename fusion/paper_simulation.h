// The simulation of section 3.3 of Liu, Zhang, Qu (2015): 100 random robot positions in a
// 100 mm cube, each measured by the photogrammetry system (sigma 0.15 mm per axis) and by
// the robot (sigma 0.157, 0.087, 0.043 mm), fused by MOIFA and by the paper's KF scheme,
// repeated over Monte-Carlo repetitions. Used by `mcms paper fusion` and its test.
//
// What the estimators are.
//  - MOIFA: eq. 15-19 with the corrected weights (fusion/moifa.h), point by point.
//    Analytically the composite RMS falls from sqrt(3) 0.15 = 0.260 mm to 0.138 mm, a
//    46.8 % reduction (the paper reports 46.1 %).
//  - KF, static: the paper's per-sensor random-walk filters (eqs. 1-5) with no process noise,
//    told the commanded displacement between points, then eq. 14. The filter then treats
//    the 100 measurements as 100 looks at one unchanging offset, and its estimate at point k
//    averages the errors of points 1..k: the error falls as 1/sqrt(k), RMS over the run
//    sigma sqrt(H_N / N) = 0.228 sigma for N = 100 (H_N the harmonic number), a 77 %
//    reduction from averaging over time alone, the size of the paper's 78.2 %. It is not
//    like for like with MOIFA: MOIFA fuses two single measurements of one point, the static
//    KF averages measurements of 100 different points, which is only valid if the errors
//    were one constant offset (then the random errors simulated here would not exist).
//  - KF, tracking: the same filters with process noise matched to a state that really
//    jumps between independent points (Q = cube_size^2 per axis per step, >> R) and no
//    knowledge of the motion: the gain tends to 1, each filter returns its latest
//    measurement and eq. 14 reduces to MOIFA. This is the like-for-like KF figure.
//
// The paper's "three-sigma rule" (section 3): per axis, errors farther than 3 sigma from
// the mean are rejected as gross errors and the accuracy is 3 sigma of the rest; the
// composite is 3 sqrt(sigma_x^2 + sigma_y^2 + sigma_z^2). RMS is sqrt(mean |e|^2).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/io.h"
#include "core/pose_math.h"

namespace mcms {

struct PaperFusionOptions {
  int num_points = 100;
  double cube_size = 0.100;                                // m
  Vec3 camera_sigma = Vec3::Constant(0.15e-3);             // m per axis
  Vec3 robot_sigma = Vec3(0.157e-3, 0.087e-3, 0.043e-3);  // m per axis
  int repetitions = 200;
  uint64_t seed = 1;
  bool IsValid(std::string* why = nullptr) const;
};

// Error statistics of one estimator, pooled over all points and repetitions (m).
struct ErrorStats {
  Vec3 rms_axis = Vec3::Zero();
  double rms = 0.0;  // composite, sqrt(mean |e|^2)
  Vec3 three_sigma_axis = Vec3::Zero();
  double three_sigma = 0.0;  // composite, paper's three-sigma rule
};

// A reduction 1 - error(estimator) / error(reference), as a fraction.
struct Reduction {
  double pooled = 0.0;          // from the pooled statistics
  double mean = 0.0;            // mean of the per-repetition reductions
  double standard_error = 0.0;  // standard deviation of those / sqrt(repetitions)
};

struct PaperFusionResult {
  PaperFusionOptions options;
  ErrorStats camera, robot, moifa;
  ErrorStats kf_static_camera, kf_static_robot, kf_static_fused;
  ErrorStats kf_tracking_camera, kf_tracking_robot, kf_tracking_fused;

  // Relative to the raw camera error.
  Reduction moifa_rms, moifa_three_sigma;
  Reduction kf_static_rms, kf_static_three_sigma;      // fused static KF vs raw camera
  Reduction kf_static_filter_rms;                      // camera's static KF vs raw camera
  Reduction kf_tracking_rms, kf_tracking_three_sigma;  // fused tracking KF vs raw camera
  // Relative to the camera's own filtered error (the paper's (dx1 - dxf) / dx1).
  Reduction kf_static_vs_filtered_camera_rms, kf_static_vs_filtered_camera_three_sigma;

  // Analytic values for these options.
  double analytic_moifa_rms_reduction = 0.0;
  double analytic_static_kf_factor = 0.0;             // sqrt(H_N / N)
  double analytic_kf_static_rms_reduction = 0.0;      // 1 - factor * (1 - moifa)
  double analytic_kf_static_filter_reduction = 0.0;   // 1 - factor
};

// InputError when the options are invalid.
PaperFusionResult SimulatePaperFusion(const PaperFusionOptions& options);

// 1 - sqrt(sum_k 1 / (1/c_k^2 + 1/r_k^2)) / sqrt(sum_k c_k^2): the expected reduction of the
// composite RMS (and of the composite three-sigma figure) by MOIFA of two sensors with
// independent per-axis errors.
double AnalyticMoifaRmsReduction(const Vec3& camera_sigma, const Vec3& robot_sigma);

// sqrt(H_N / N): RMS over steps 1..N of the error of a running mean, in units of one
// measurement's sigma (the static KF started from its first measurement).
double RunningMeanRmsFactor(int n);

// `mcms paper fusion`'s inputs and report. The published figures file: `given` (must exist;
// InputError otherwise), else $MCMS_DATA_DIR/paper/fusion_results.csv, else
// ../shared/data/paper/fusion_results.csv from the working directory; nullopt when none
// exists, with the places looked at in `looked`.
std::optional<std::filesystem::path> FindPaperResults(const std::string& given, std::string* looked);
// Table 3 ours (three-sigma rule and RMS), the analytic figures, the paper's figures from
// `paper_table` (its fusion_results.csv; when null, a line naming `looked`), and the notes
// with the weights of the printed and of the correct eq. 13 for these options.
std::string FormatPaperFusionReport(const PaperFusionOptions& o, const PaperFusionResult& r,
                                    const CsvTable* paper_table, const std::string& looked);

}  // namespace mcms
