// Measured repeatability confronted with the predicted map (issue 12, part 2): repeated
// measurements of target points (the paper's Table 1, or raw repeats), the nominal
// model's prediction at the same points, and the candidate causes of their disagreement
// fitted by maximum likelihood.
//
// Statistics. The sample variance v of n repeats of a normal quantity with variance s2 is
// Gamma distributed: (n - 1) v / s2 ~ chi-square(n - 1). Every point contributes its three
// per-axis sample variances (the axes treated as independent, which a diagonal covariance
// makes exact). The variance model of point i on axis a is
//     s2_ia = k^2 * nominal_ia + floor^2 + g_a^2             (inliers)
//     s2_ia + o^2                                             (a misidentified point, prob. pi)
// with the effects
//     pixel_noise_scale   k          (nominal: k = 1): the centre noise scaled
//     noise_floor         floor (m)  distance-independent: vibration, robot repeatability,
//                                    time synchronisation between the cameras
//     anisotropy_x|y|z    g_a (m)    extra noise along one rig axis
//     misidentification   pi, o (m)  a point whose repeats mix misidentified balls (the edge
//                                    of the view): a two-component mixture per point
// Effects are added greedily while the extended BIC falls (Chen & Chen 2008: -2 log L +
// p ln N + 2 ln C(K, k), N = number of sample variances, k of K candidate effects; the last
// term keeps the search over K candidates from raising the false alarms); the held-out gain is the leave-one-point-out log likelihood of the
// selected model (refitted without the point) minus that of the nominal model, natural
// log, summed over points.
//
// Layout. Table 1 gives no coordinates. The layout assumed (PaperLayout): 5 horizontal
// planes, plane 1 at 2.0 m below the cameras and plane 5 at 1.0 m, evenly spaced; on each a
// 3 x 3 grid of points 0.5 m apart in x and 0.4 m apart in y (the 500 and 400 mm lines of
// Table 2) centred under the rig, numbered consecutively through the planes (plane 1:
// points 1-8, plane 5: 35-43) around the perimeter from a corner (corner, edge, corner, ...,
// then the centre), so that corners are the odd points 1, 3, 5, 7 as the paper says; the
// paper's axes are the rig's (z vertical). AnalyseMeasured refits under variants of this
// layout and reports how the conclusion moves.
#pragma once

#include <cmath>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "synthetic/camera_error_model.h"
#include "vision/camera_model.h"

namespace mcms {

struct MeasuredPoint {
  int plane = 0;                 // 0 when the input names none
  std::string id;                // the point's label in the input
  int repeats = 0;
  Vec3 variance = Vec3::Zero();  // sample variances per axis (n - 1 denominator), m^2
  std::optional<Vec3> mean_rig;  // mean measured position (raw input), m
  std::optional<Vec3> reference; // reference position (--reference), m
};

struct MeasuredPoints {
  std::filesystem::path source;
  bool from_table = false;  // sigmas given (Table 1) rather than raw repeats
  std::vector<MeasuredPoint> points;
};

// Table 1 (plane,point,sigma_x_mm,sigma_y_mm,sigma_z_mm[,sigma_d_mm]; every sigma from
// `table_repeats` repeats) or raw (point,repeat,x_m,y_m,z_m[,plane]), or a poses.csv of
// mcms track with a point column added (the frame is the repeat; lost frames are skipped). InputError naming the
// file, line and column for: a missing column, a non-finite or negative number, a duplicate
// point or repeat, a point with fewer than 2 repeats, a plane with one point, sigma_d that
// is not the compound of the three, fewer than 3 points.
MeasuredPoints ReadMeasuredPoints(const std::filesystem::path& path, int table_repeats = 5);
// Reference coordinates (point,x_m,y_m,z_m). InputError when a measured point has no
// reference, the reference names a point that was not measured, or the measurements are
// Table 1 sigmas (no mean position to compare).
void ApplyReference(MeasuredPoints* points, const std::filesystem::path& path);

struct MeasuredLine {
  int plane = 0;
  std::string id;
  double d_reference_m = 0, d_measured_m = 0;
  std::string from, to;  // end points when the input names them (columns from,to)
};
struct MeasuredLines {
  std::filesystem::path source;
  std::vector<MeasuredLine> lines;
};
// Table 2 (plane,line,d_laser_mm,d_camera_mm[,delta_mm][,from,to]). InputError as above,
// and when delta_mm disagrees with d_laser_mm - d_camera_mm.
MeasuredLines ReadMeasuredLines(const std::filesystem::path& path);
// InputError naming the lines file, the line and what the measurements hold when a line
// joins a point that was not measured (columns from,to) or lies on a plane the measured
// points lack (when they name planes).
void CheckLinesAgainstPoints(const MeasuredLines& lines, const MeasuredPoints& points);

// ---- The noise-model fit (independent of files, for tests) ----

struct VarianceData {
  std::vector<Vec3> nominal;   // predicted variance per axis, m^2
  std::vector<Vec3> measured;  // sample variance per axis, m^2
  std::vector<int> repeats;
  size_t size() const { return measured.size(); }
};

// The candidate effects, in the order tried.
const std::vector<std::string>& CandidateEffects();

struct NoiseModelFit {
  std::vector<std::string> effects;  // selected, in the order added
  double scale = 1, floor = 0, outlier_probability = 0, outlier_sigma = 0;
  Vec3 anisotropy = Vec3::Zero();    // g_x, g_y, g_z (m)
  double loglik = 0, bic = 0;       // bic: the extended BIC above
  int num_parameters = 0;
  size_t num_variances = 0;
  // Standard errors (observed information) of the named parameters.
  std::vector<std::pair<std::string, double>> parameters, standard_errors;
  std::vector<double> outlier_posterior;  // per point, P(misidentified | data)
  std::string selection_log;              // one line per greedy step
  Vec3 InlierVariance(const Vec3& nominal) const;
  // Log density of one point's three sample variances.
  double PointLogLik(const Vec3& nominal, const Vec3& measured, int repeats) const;
};

// Log density of one point's sample variances when the true per-axis variance is s2.
double SampleVarianceLogLik(const Vec3& measured, const Vec3& s2, int repeats);

// Fits the given effects (all others at their nominal values) by maximum likelihood.
NoiseModelFit FitNoiseModel(const VarianceData& data, const std::vector<std::string>& effects);
// Greedy forward selection by the extended BIC from the nominal model over `candidates` (default all).
NoiseModelFit SelectNoiseModel(const VarianceData& data, const std::vector<std::string>& candidates = {});
// Leave-one-point-out: per point, the log density under the effects refitted without it.
std::vector<double> HeldOutLogLik(const VarianceData& data, const std::vector<std::string>& effects);

// ---- The whole analysis ----

struct PaperLayout {
  std::string name = "assumed";
  double first_plane_distance_m = 2.0, last_plane_distance_m = 1.0;  // below the cameras' mean height
  int planes = 5;
  double dx_m = 0.5, dy_m = 0.4;
  bool perimeter_numbering = true;  // false: row by row
  int axis_of_paper[3] = {0, 1, 2};  // rig axis of the paper's x, y, z
  int first_point_of_plane(int plane, const std::vector<MeasuredPoint>& points) const;
};

struct MeasuredAnalysisOptions {
  double plane_first_distance_m = 2.0, plane_last_distance_m = 1.0;
  double paper_isotropic_sigma_m = 0.15e-3;  // the paper's own fusion simulation (section 3.3)
  double laser_sigma_m = 0.01e-3;            // FARO Xi ADM 10 um (+ 1.1 um/m)
  int repeats_per_line_end = 5;              // a line's measured length uses the mean of its ends' repeats
  bool sensitivity = true;                   // refit under layout variants
  int lab_seeds = 5;                         // the lab experiment with the fitted camera (0 = skip)
  bool IsValid(std::string* why) const;
};

struct LayoutResult {
  std::string layout;
  std::vector<std::string> effects;
  double heldout_gain = 0;  // extended vs nominal
  double heldout_gain_vs_isotropic = 0;
  std::string parameters;   // one line
  int untrackable_nominal = 0;
};

struct LinePrediction {
  MeasuredLine line;
  Vec3 direction = Vec3::UnitX();  // rig frame, assumed or from the end points
  double predicted_sd_m = 0;       // inlier standard deviation of delta
  double outlier_probability = 0;  // either end misidentified
  double z = 0;                    // delta / predicted_sd
  bool gross = false;              // beyond 3 x the largest inlier sd any direction allows
};

struct Table2Prediction {
  std::string variant;  // the line directions and averaging assumed
  std::vector<LinePrediction> lines;
  double gross_threshold_m = 0;
  int inliers = 0;      // lines that are not gross
  double measured_mean_abs_m = 0, predicted_mean_abs_m = 0, predicted_mean_abs_sd_m = 0;  // over those
  double loglik_extended = 0, loglik_nominal = 0, loglik_isotropic = 0;                     // over all lines
};

struct LabReductionResult {
  std::string camera_model;
  int seeds = 0;
  double camera_3sigma_m = 0, robot_3sigma_m = 0, moifa_3sigma_m = 0, kf_3sigma_m = 0;
  double moifa_reduction = 0, moifa_reduction_sd = 0, kf_reduction = 0, kf_reduction_sd = 0;
};

struct MeasuredReport {
  MeasuredPoints measured;
  std::vector<Vec3> positions_rig;   // assumed (Table 1) or measured means (raw)
  std::vector<Vec3> nominal_sigma;   // m, per axis; the nominal model's prediction
  std::vector<bool> nominal_trackable;
  std::vector<double> nominal_border_px;  // nearest approach of a ball image to an image border (nominal rig)
  VarianceData data;
  NoiseModelFit fit;
  std::vector<double> heldout_extended, heldout_nominal, heldout_isotropic;
  double heldout_gain = 0, heldout_gain_vs_isotropic = 0;
  double loglik_nominal = 0, loglik_isotropic = 0;
  std::vector<LayoutResult> sensitivity;
  Table2Prediction table2;                      // under the assumed layout
  std::vector<Table2Prediction> table2_variants;  // other line directions and averaging
  std::vector<LabReductionResult> lab;  // nominal and fitted camera (empty when skipped)
  std::string layout_text;
  std::string text;  // the human-readable report
};

// What the forward model predicts at a position of the target (rig frame): whether the
// rig tracks it there, the pose covariance ([dtheta; dp], rig frame), and the nearest
// approach of a ball image to an image border (px). The job gives it (jobs/fov_map.h: the
// tracker's Cramer-Rao covariance of the mapped rig).
struct PointPrediction {
  bool trackable = false;
  Mat6 cov = Mat6::Constant(std::nan(""));
  double min_border_px = 0.0;
  Vec3 SigmaPosition() const { return cov.bottomRightCorner<3, 3>().diagonal().cwiseSqrt(); }
};
using PredictPoints = std::function<std::vector<PointPrediction>(const std::vector<Vec3>& positions_rig)>;
// The paper's lab experiment with a camera error model (jobs/fov_map_lab.h); empty: none.
using PredictLab =
    std::function<std::vector<LabReductionResult>(const CameraErrorModel& model, const Mat6& centre_cov, int seeds)>;

// The analysis: the measured variances against `predict`'s at the points' positions (the
// measured means, or the assumed layout under the cameras of `rig`), the effects selected,
// held-out gains, the layout's sensitivity, Table 2 and, with `lab`, the lab experiment
// with the fitted camera.
MeasuredReport AnalyseMeasured(const MeasuredPoints& measured, const MeasuredLines* lines, const CameraRig& rig,
                               const PredictPoints& predict, const PredictLab& lab = {},
                               const MeasuredAnalysisOptions& options = {});

// The camera error model of a fit (the misidentification effect is left out: see
// synthetic/camera_error_model.h).
CameraErrorModel CameraErrorModelFromFit(const NoiseModelFit& fit, const std::string& name, const std::string& source);

// measured.csv, measured_fit.txt, measured_sigma.svg, and lines.csv when lines were given.
void WriteMeasuredReport(const MeasuredReport& report, const std::filesystem::path& dir);
// {"effects": [{"name", "parameters", "sigma"}], "heldout_loglik_gain", ...}
void WriteMeasuredJson(const MeasuredReport& report, const std::filesystem::path& path);

}  // namespace mcms
