// The result of a model audit (issue 11), common to every mode (robot, cameras, fusion):
// how well the nominal model explains the measured data, the effects from the catalog
// (model/extensions.h) that earned their place, and the candidates that could not be told
// apart. Written as text for people and as JSON for scripts:
//   {"mode": .., "nominal": {"chi2_per_dof": .., "n": ..}, "clean": true|false,
//    "effects": [{"name", "where", "parameters": {..}, "sigma": {..}, "heldout_rms_before",
//                 "heldout_rms_after", "heldout_loglik_gain", "bic_gain"}],
//    "undecided": [[name, name], ..], "undecided_effects": [[{effect}, ..], ..],
//    "tests": [..], "tests_after": [..] (robot, cameras: still failing with the final model),
//    "notes": [..], "validation": [..] (model/robot_validation.h; when scored)}
//   (an effect may also carry "held": {name: reason})
// Units: parameters and sigmas in SI (rad, m, s, dimensionless factors); held-out RMS in
// the unit the mode states in `rms_unit` (m for robot positions, px for cameras).
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "model/robot_validation.h"

namespace mcms {

// One statistical test of the nominal residuals (chi-square, runs, autocorrelation, a
// trend against a covariate): its statistic, p-value and whether it failed at `alpha`.
struct AuditTest {
  std::string name;       // e.g. "chi-square", "runs in time", "trend vs joint 2"
  double statistic = 0.0;
  double p_value = 1.0;
  bool failed = false;
};

struct AuditEffect {
  std::string name;   // catalog name, e.g. "joint_offset"
  std::string where;  // "joint 2", "a2", "cam1", "ball 3", a sensor's name; empty when global
  std::vector<std::pair<std::string, double>> parameters, sigma;  // SI, in the unit's order
  // Each parameter's SI unit where the mode gives it ("rad", "m", "s", ""; index-aligned
  // with parameters, or empty): the text shows rad in mrad and m in mm, to the digits its
  // sigma carries (JSON stays SI).
  std::vector<std::string> units;
  // Parameters that are names, not numbers (the lens audit: the chosen lens model);
  // written into "parameters" beside the numbers.
  std::vector<std::pair<std::string, std::string>> labels;
  // Parameters of the effect that the data cannot identify, held at their nominal value,
  // with the reason (the robot audit's `geometry`: "not identifiable: a combination of ...").
  std::vector<std::pair<std::string, std::string>> held;
  double heldout_rms_before = 0.0, heldout_rms_after = 0.0;
  double heldout_loglik_gain = 0.0;  // summed over held-out measurements (nats)
  double bic_gain = 0.0;             // BIC(before) - BIC(after) on all data (> 0 = earns its place)
  std::string rms_unit;              // unit of the held-out RMS when not the report's (fusion: rad)
};

// Every likelihood ratio of a fitted model against a model it contains (issue 51): a model
// with more free parameters never fits worse, so a ratio below -kTolerance times the
// contained model's |log-likelihood| (at least 1) is a failed solve, never evidence.
// JSON "nested_fits": {"count", "worst_relative_lr", "failed"}.
struct NestedFits {
  static constexpr double kTolerance = 1e-6;
  long count = 0;
  double worst_relative_lr = 0.0;  // the lowest lr / max(1, |loglik of the contained model|)
  long failed = 0;
  // Records one comparison; false when it is a failed solve.
  bool Record(double lr, double contained_loglik);
  void Merge(const NestedFits& o);
};

struct AuditReport {
  std::string mode;             // "robot", "cameras", "fusion"
  double nominal_chi2_per_dof = 0.0;
  long nominal_n = 0;           // residuals (scalar) the chi-square is over
  std::string rms_unit = "m";
  bool clean = true;            // no effect named and no test failed
  std::vector<AuditTest> tests;
  // The robot audit: the same residual tests on the final model's residuals, those that
  // still fail (what the catalog leaves unexplained); JSON "tests_after". `tests_after_run`
  // counts the tests run (0 = not run).
  std::vector<AuditTest> tests_after;
  int tests_after_run = 0;
  std::vector<AuditEffect> effects;
  std::vector<std::vector<std::string>> undecided;  // groups of "name at where" labels
  // The same groups with each member's fitted size (parameters, sigma, gains), when the
  // mode gives them (the robot audit); index-aligned with `undecided`, or empty.
  std::vector<std::vector<AuditEffect>> undecided_effects;
  std::vector<std::string> notes;                   // what the audit could not test, and why
  // Other sessions scored with the fitted models frozen (the robot audit's --validate):
  // JSON "validation" (model/robot_validation.h).
  std::vector<SessionScore> validation;
  NestedFits nested;

  // Appends another audit of the same data set (fusion: the inclinometer beside the
  // tracker and robot): its tests, effects (with its rms_unit), undecided groups and notes;
  // clean when both are; the nominal chi2/dof is the average over both's residuals.
  void Merge(const AuditReport& other);
  std::string ToJson() const;
  // Human text: the tests, each effect with its size +- sigma and gains, the undecided groups.
  std::string Text() const;
  void WriteJson(const std::filesystem::path& path) const;  // atomically
};

}  // namespace mcms
