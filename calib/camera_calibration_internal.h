// What the rig calibration's files share (calib/camera_calibration.h is the entry).
#pragma once

#include "calib/camera_calibration.h"

namespace mcms {

// One lens model (options.lensmodel, not "auto"), all steps: the observations validated,
// initial values, the least-squares problem solved with outlier rejection, the solution,
// its covariance. InputError for a lens model that cannot be calibrated here.
CameraCalibrationResult CalibrateWithLensModel(const CameraCalibrationInput& input,
                                               const CameraCalibrationOptions& options);

// The largest sigma of a distortion coefficient (intrinsics beyond the first 4) over the
// rig's cameras: how well the data pin the lens model down.
double LargestDistortionStd(const CameraCalibrationResult& r);

}  // namespace mcms
