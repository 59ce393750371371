// Another session, frozen: a robot model fitted on one log (its registration, the tool's
// points, the geometry, each effect) scored unchanged on another log measured in the same
// frame, as metrologists judge a model: by what it predicts on data it was not fitted to.
// Used by `calib-robot --validate` and `audit robot --validate`.
//
// Scores are per point of the measured body (3-D distance between predicted and measured,
// RMS and max, m) and per posture group (calib/robot_measurements.h PostureGroups: repeated
// from the fitted log, new inside its joint ranges, out of range).
// JSON: {"log", "rows", "models": [{"model", "points": [{"point", "rows", "rms_mm", "max_mm"}],
//        "groups": {"repeated": {"rows", "points": [..]}, "new_in_range": .., "out_of_range": ..}}]}
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "calib/robot_measurements.h"
#include "core/pose_math.h"

namespace mcms {

struct PointScore {
  int point = 1;  // 1-based
  int rows = 0;
  double rms_m = 0.0, max_m = 0.0;
};

struct ModelScore {
  std::string model;  // "registration", "geometry", "final"
  std::vector<PointScore> points;
  std::vector<std::pair<PostureGroup, std::vector<PointScore>>> groups;  // the groups with rows
  // Per row, each point's error (predicted - measured, m): for plots.
  std::vector<std::vector<Vec3>> errors;
};

struct SessionScore {
  std::string log;
  int rows = 0;
  std::vector<PostureGroup> group_of_row;
  std::vector<ModelScore> models;
};

// The score of one model from its per-row point errors (rows x points).
ModelScore ScoreModel(const std::string& model, const std::vector<std::vector<Vec3>>& errors,
                      const std::vector<PostureGroup>& groups);

// Text for reports: per session, per model, point 1's RMS / max overall and per group, then
// every point's RMS.
std::string ValidationText(const std::vector<SessionScore>& sessions);
// The JSON array of the header.
nlohmann::json ValidationJson(const std::vector<SessionScore>& sessions);

}  // namespace mcms
