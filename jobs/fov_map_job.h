// The whole `mcms fov-map` job as a library function (the command only parses options):
// what is mapped (scenario, rig, target, noise options), the predicted map, the optional
// Monte Carlo and the optional measured-data fit, the report on a text stream, and the
// output folder written as a whole (core/io.h WriteFolderAtomically).
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "audit/repeatability.h"
#include "core/pose_math.h"
#include "jobs/fov_map.h"
#include "jobs/job.h"

namespace mcms {

// The measured-repeatability analysis (audit/repeatability.h) against this rig's predicted
// map (the tracker's Cramer-Rao covariance, PredictFovPoints) and, when options.lab_seeds
// > 0, the paper's lab experiment with the fitted camera (jobs/fov_map_lab.h).
MeasuredReport AnalyseMeasuredAgainstRig(const MeasuredPoints& measured, const MeasuredLines* lines,
                                         const CameraRig& rig, const Target& target, const FovMapOptions& map_options,
                                         const MeasuredAnalysisOptions& options = {});

// The default grid: the demo rig's 1 x 0.8 x 1 m working volume, rig frame, metres.
inline constexpr const char* kDefaultFovGrid = "-0.5:0.5:11,-0.4:0.4:9,0:1:11";

struct FovMapJob {
  std::filesystem::path output;                    // the output folder (required)
  std::filesystem::path scenario, rig, target;     // empty: the built-in scenario's
  std::string grid;                                // x0:x1:n,y0:y1:n,z0:z1:n; empty: kDefaultFovGrid
  Vec3 orientation_rad = Vec3::Zero();             // target orientation (rotation vector, rig frame)
  // Image formation overrides; a negative value keeps the scenario's (read_noise: 0 keeps).
  double gain = -1, read_noise = 0, ball_dn = -1, background_dn = -1, blur_px = -1;
  double threshold_mm = 0.03;
  int threads = 1;
  int simulate = 0, repeats = 30;                  // Monte Carlo points and frames per point
  uint64_t seed = 1;
  // Measured data (optional).
  std::filesystem::path measured, lines, json, reference;
  int measured_repeats = 5;
  double plane_first_distance_m = 2.0, plane_last_distance_m = 1.0;
  bool quiet = false;                              // no progress on stderr
};

// Runs the job, giving its report to out.print. InputError naming the input (and nothing
// written) on bad input; outputs are checked writable before the work.
void RunFovMapJob(const FovMapJob& job, const JobOutput& out);

}  // namespace mcms
