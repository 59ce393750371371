// Which parameters a set of measurements determines: a greedy analysis of the Jacobian's
// columns (calib-robot's calibration and the robot audit both stand on it).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace mcms {

// A parameter's status in the analysis: held (fixed) with the reason, or estimated.
struct ParameterStatus {
  bool fixed = false;   // on entry: held by request (skipped); on exit: also held by the analysis
  std::string reason;   // why it is held; empty when estimated
};

// The greedy identifiability analysis on a Jacobian whose columns are in priority order (the calibration puts base and tool first, then the joints from
// the base out; the robot audit does the same): a column whose relative distance from the
// span of the columns kept before it is below `tol`, or that is zero, is marked fixed in
// `status` (index-aligned with the columns) with the reason, naming the kept parameters it
// is a combination of. Parameters already fixed (by request) are skipped. With
// `largest_sigma` (index-aligned; 0 = no limit) and J whitened by the measurements' noise
// (so that (J^T J)^-1 is the parameters' covariance): then, one at a time, the kept
// parameter whose standard deviation exceeds its largest_sigma by the most is held, with
// the reason "weakly identifiable", until none does.
void AnalyzeIdentifiability(const Eigen::MatrixXd& J, const std::vector<std::string>& names, double tol,
                            std::vector<ParameterStatus>* status,
                            const std::vector<double>& largest_sigma = {});

}  // namespace mcms
