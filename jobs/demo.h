// The demo: the paper's lab experiment (section 3.4) on the forward model, end to end.
// Renders the 4-camera rig watching the five-ball target on a KUKA KR 5 arc that visits
// points on a 200 mm sphere with dwells, tracks every rendered frame, writes the tracker,
// robot and inclinometer logs with the setup and the dwell windows, fuses those files by
// the one fusion path `mcms fuse` runs (fusion/log_fusion.h FuseLogFiles, MOIFA and KF per
// dwell), reports each sensor alone and each fused result against the truth by the
// paper's three-sigma rule, with plots like its Figures 7 and 8, then runs the ISO 9283
// experiment (jobs/iso9283_experiment.h).
//
// Camera model (--camera-model, synthetic/camera_error_model.h): the frames are rendered with
// the model's pixel noise and with the target shown where each visit's rigid error puts it;
// the tracker's covariance gets the visit covariance; the truth stays the true flange. The
// summary sets the reductions (with their bootstrap sd over the points) beside the paper's.
//
// Files written to `out`:
//   tracker_poses.csv      what `mcms track` writes (T_rig_target with covariance)
//   robot_joints.csv       encoder readings, time_s,q1_rad..q6_rad
//   inclinometer.csv       time_s,tilt_x_rad,tilt_y_rad
//   fusion_setup.yaml      T_base_rig, T_flange_target, inclinometer, robot accuracy, KF
//   dwells.csv             start_s,end_s of every dwell (the fusion windows)
//   fused_poses.csv        the fused rows; `mcms fuse --tracker tracker_poses.csv --robot
//                          robot_joints.csv --inclinometer inclinometer.csv --setup
//                          fusion_setup.yaml --windows dwells.csv -o F` writes the same file
//   camera_model.txt       the camera error model rendered (--camera-model)
//   summary.txt, point_errors.csv, position_error_per_point.svg,
//   orientation_error_per_point.svg, and the ISO 9283 files (iso9283_*).
#pragma once

#include <filesystem>
#include <functional>
#include <string>

#include "synthetic/camera_error_model.h"
#include "jobs/iso9283_experiment.h"
#include "jobs/job.h"
#include "jobs/lab_experiment.h"

namespace mcms {

struct DemoOptions {
  std::filesystem::path out = "mcms-demo";
  int points = 76;                // on the sphere (paper: 76)
  double camera_rate_hz = 1.0;    // rendered frames per second
  bool save_images = false;       // also write the rendered recording (PNG)
  LabExperimentOptions experiment;
  // The camera's error model (synthetic/camera_error_model.h): ideal (the nominal rig), or
  // made as bad as a measured one (--camera-model paper|FILE).
  CameraErrorModel camera_model;
  bool iso9283 = true;            // also run the ISO 9283 experiment
  bool quiet = false;             // no progress on stderr
  int threads = 0;                // render threads; 0: the hardware's
  bool IsValid(std::string* why = nullptr) const;
};

struct DemoResult {
  LabResult lab;
  std::string lab_report;   // the tracker summary and the lab table (summary.txt)
  std::string iso_report;   // empty when not run
  std::vector<double> reduction_sd;  // per method of lab.summary: bootstrap sd over the points
  std::string paper_report;  // the run against the paper's lab result (also in summary.txt)
};

// InputError on invalid options or an unusable output folder (checked before the
// simulation). out.print receives the text to show, as it becomes available (jobs/job.h;
// the one job that returns a result: the tests read its figures).
DemoResult RunDemo(const DemoOptions& options, const JobOutput& out);

}  // namespace mcms
