// The whole `mcms audit cameras` job: track a recording (as `mcms track`), audit the camera
// model against it (audit/camera_audit.h), and write what was asked: the JSON report, the
// output folder (report, whitened residuals, plots), the repaired rig and target.
#pragma once

#include <filesystem>
#include <functional>
#include <string>

#include "audit/camera_audit.h"
#include "jobs/job.h"
#include "tracking/noise_estimate.h"

namespace mcms {

struct CameraAuditJob {
  std::filesystem::path recording;  // images/, rig.yaml, target.yaml, optional frames.csv
  std::filesystem::path repaired_rig, repaired_target, json, output;  // empty: not written
  CameraAuditOptions audit;
  double rate_hz = 10.0;  // when there is no frames.csv
  bool quiet = false;     // no progress on stderr
  RecordingTrackerSettings tracker;
};

// `print` receives the text to show. InputError (nothing written) on bad input; every
// output is checked writable before the work, every repaired file before any is written.
void RunCameraAuditJob(const CameraAuditJob& job, const JobOutput& out);

// The output folder's contents: report.txt, report.json, residuals.csv (every camera's
// whitened leave-one-out residuals with their covariates) and plots/<camera>.svg (the
// residuals against each covariate the audit tests, and as vectors over the image).
void WriteCameraAuditFolder(const std::filesystem::path& out, const CameraRig& rig, const CameraAuditResult& audit);

}  // namespace mcms
