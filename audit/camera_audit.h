// The camera mode of the model audit (issue 11): which part of the camera model a tracked
// recording contradicts, named from the catalog of model/extensions.h, with its size, its
// standard deviation and the gain it brings on held-out data.
//
// Data. Every frame with a pose gives the ball images of every camera (the nearest blob to
// each predicted ball image, within a gate). Two leave-one-out views of them:
//  - per camera c: the frame's pose re-fitted without camera c, camera c's ball images
//    predicted from it (camera effects: camera_moved, focal_length, principal_point,
//    radial_distortion, camera_time_offset, pixel_noise_scale);
//  - per ball b: the pose re-fitted without ball b, ball b's images in every camera
//    predicted from it (target_geometry), so that the pose cannot absorb the ball's error.
// Each residual is whitened with the blob's covariance plus the leave-one-out pose's
// covariance carried into the prediction, scaled by the camera's pixel noise factor s_c^2.
//
// The noise model first: s_c is always estimated (a nuisance parameter of every fit), so a
// noise model that is off does not make geometric terms look significant; the effect
// pixel_noise_scale is named when s_c is outside [1/(1+tol), 1+tol] beyond chance.
//
// Selection. Every candidate (each camera effect at each camera, target_geometry at each
// ball, and camera_moved from a change time on: a camera bumped part-way through) is fitted
// with the unit's effects already named (Ceres least squares through the extension units,
// numeric derivatives of the mrcal projection), on all data and on k folds that are
// contiguous blocks of time. The decision of each round is the audit's one selection
// rule (audit/model_selection.h DecideStep): a candidate passes when, on all data, its
// likelihood ratio passes chi-square at alpha / (2 m) (m candidates, times the scanned
// change times for a part-way move: Bonferroni, so a clean recording is flagged with
// probability <= alpha together with the chi-square tests at alpha / (4 cameras) and the
// residual tests, lag-1 autocorrelation and trends against time, the position in the view
// and the distance to the camera, at alpha / 4 over their number) and its
// BIC gain is > 0; among those within 2 undecided_nats of the best BIC gain with a
// positive held-out gain, the largest held-out gain is named. Greedy forward selection
// re-fits the leave-one-out poses with the extended model and repeats; at the end an
// effect that no longer earns its place with the others in is removed (backward pruning,
// said in the notes). When a candidate of another kind on the same data (the same
// camera, or the same ball) is within `undecided_nats` of the best's held-out gain and
// 2 undecided_nats of its BIC gain, neither is named: the group is reported as
// undecided (the best of it is kept in the model, unnamed, so that its residual does not
// leak into the other cameras' poses) and that place is not searched further. A simpler
// candidate that fits as well wins on BIC and is no tie (a small tilt of a camera and a
// principal-point shift are the same image shift: principal_point).
// A late camera's effect on the other cameras' poses is removed by moving its blobs back
// by the named offset; target_geometry is not written into the rig (ExtendedTarget).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "audit/camera_audit_types.h"

namespace mcms {

// `log` (may be empty) receives one line per selection round.
CameraAuditResult AuditCameraModel(const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results,
                                   const CameraAuditOptions& options = {},
                                   const std::function<void(const std::string&)>& log = {});

}  // namespace mcms
