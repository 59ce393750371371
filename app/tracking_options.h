// CLI options shared by the commands that run the tracker (track, audit).
#pragma once

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <vector>

#include "tracking/noise_estimate.h"
#include "tracking/sequence.h"
#include "tracking/tracker.h"

namespace mcms::app {

struct TrackerCli {
  std::optional<double> gain_e_per_dn;  // absent: measured from the recording's images
  double read_noise_dn = 0;
  std::string polarity = "bright";
  double threshold_dn = 0;
  size_t noise_frames = 12;
  int threads = 0;  // 0 = the machine's cores
  bool predicted_windows = false;

  void Add(CLI::App* cmd);
  int Threads() const;
  // The library's settings (tracking/noise_estimate.h) from these options.
  RecordingTrackerSettings Settings() const;
};

}  // namespace mcms::app
