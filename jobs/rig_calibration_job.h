// The whole `mcms calib-rig` job: calibration-board images per camera -> every camera's
// intrinsics and pose in the rig (camera 0 = rig frame), as mrcal .cameramodel (with
// mrcal's optimization_inputs for chessboards), OpenCV YAML and rig.yaml, with a residual
// summary and per-camera residual plots. The lens model is chosen by the data unless
// given; a solve that did not converge writes nothing, nor (without allow_poor_fit) one
// that CalibrationProblems finds untrustworthy. Symmetric chessboards are renumbered per
// frame to agree across the cameras, and every renumbering is reported.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "calib/camera_calibration.h"
#include "jobs/job.h"

namespace mcms {

struct RigCalibrationJob {
  std::filesystem::path board;                  // board description (Kalibr YAML)
  std::vector<std::filesystem::path> folders;   // one image folder per camera (its name names it)
  std::filesystem::path output = "calib-rig";
  std::string lensmodel = "auto";
  int max_iterations = 200;
  double outlier_k = 4.0;
  double range_m = 10.0;  // range of the projection-uncertainty report
  bool board_warp = false;
  bool quiet = false;     // no progress or log on stderr
  CalibrationQualityLimits limits;
  bool allow_poor_fit = false;
};

// `print` receives the report (stdout of the command); progress and the solver's log go
// to stderr unless quiet. InputError naming the input on bad input, nothing written.
void RunRigCalibrationJob(const RigCalibrationJob& job, const JobOutput& out);

}  // namespace mcms
