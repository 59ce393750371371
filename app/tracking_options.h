// CLI options shared by the commands that run the tracker.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "tracking/tracker.h"

namespace mcms::app {

struct TrackerCli {
  double gain_e_per_dn = 0;
  double read_noise_dn = 0;
  std::string polarity = "bright";
  double threshold_dn = 0;

  void Add(CLI::App* cmd);
  TrackerOptions Options() const;
};

}  // namespace mcms::app
