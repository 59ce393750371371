#include "calib/robot_validation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <nlohmann/json.hpp>

namespace mcms {

namespace {

std::vector<PointScore> Score(const std::vector<std::vector<Vec3>>& errors, const std::vector<int>& rows) {
  std::vector<PointScore> out;
  if (rows.empty() || errors.empty()) return out;
  const size_t K = errors[rows.front()].size();
  for (size_t k = 0; k < K; ++k) {
    PointScore s;
    s.point = static_cast<int>(k) + 1;
    double sum = 0;
    for (int i : rows) {
      if (k >= errors[i].size()) continue;
      const double d = errors[i][k].norm();
      sum += d * d;
      s.max_m = std::max(s.max_m, d);
      ++s.rows;
    }
    s.rms_m = s.rows ? std::sqrt(sum / s.rows) : 0.0;
    out.push_back(s);
  }
  return out;
}

nlohmann::json PointsJson(const std::vector<PointScore>& p) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& s : p) a.push_back({{"point", s.point}, {"rows", s.rows}, {"rms_mm", s.rms_m * 1e3}, {"max_mm", s.max_m * 1e3}});
  return a;
}

const ModelScore* ModelNamed(const SessionScore& s, const std::string& name) {
  for (const ModelScore& m : s.models)
    if (m.model == name) return &m;
  return nullptr;
}

// Point 1 without -> with a cause, RMS / max (mm), overall and per posture group.
std::string MovedLine(const std::string& cause, const ModelScore& without, const ModelScore& with) {
  std::string out = "    " + cause + ":";
  char b[160];
  const auto Add = [&](const char* group, const std::vector<PointScore>& a, const std::vector<PointScore>& c) {
    if (a.empty() || c.empty()) return;
    std::snprintf(b, sizeof b, " %s %.3f/%.3f -> %.3f/%.3f;", group, a[0].rms_m * 1e3, a[0].max_m * 1e3,
                  c[0].rms_m * 1e3, c[0].max_m * 1e3);
    out += b;
  };
  Add("all", without.points, with.points);
  for (const auto& [g, p] : without.groups)
    for (const auto& [g2, p2] : with.groups)
      if (g == g2) Add(Name(g), p, p2);
  out.back() = '\n';
  return out;
}

// What each cause moved on the session: the geometry (registration -> geometry) and each
// model "final without X" -> "final".
std::string MovedText(const SessionScore& s) {
  std::string lines;
  const ModelScore* reg = ModelNamed(s, "registration");
  const ModelScore* geo = ModelNamed(s, "geometry");
  const ModelScore* fin = ModelNamed(s, "final");
  if (reg && geo) lines += MovedLine("geometry (registration -> geometry)", *reg, *geo);
  const std::string prefix = "final without ";
  if (fin)
    for (const ModelScore& m : s.models)
      if (m.model.rfind(prefix, 0) == 0) lines += MovedLine(m.model.substr(prefix.size()), m, *fin);
  if (lines.empty()) return lines;
  return "  what each cause moved there (point 1, RMS/max mm, without -> with it):\n" + lines;
}

}  // namespace

ModelScore ScoreModel(const std::string& model, const std::vector<std::vector<Vec3>>& errors,
                      const std::vector<PostureGroup>& groups) {
  ModelScore m;
  m.model = model;
  m.errors = errors;
  std::vector<int> all(errors.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  m.points = Score(errors, all);
  for (PostureGroup g : {PostureGroup::kRepeated, PostureGroup::kNewInRange, PostureGroup::kOutOfRange}) {
    std::vector<int> rows;
    for (size_t i = 0; i < groups.size() && i < errors.size(); ++i)
      if (groups[i] == g) rows.push_back(static_cast<int>(i));
    if (!rows.empty()) m.groups.push_back({g, Score(errors, rows)});
  }
  return m;
}

std::string ValidationText(const std::vector<SessionScore>& sessions) {
  std::string out;
  char b[256];
  for (const SessionScore& s : sessions) {
    int counts[3] = {0, 0, 0};
    for (PostureGroup g : s.group_of_row) ++counts[static_cast<int>(g)];
    std::snprintf(b, sizeof b,
                  "validation on %s (%d rows: %d repeated, %d new inside the fitted ranges, %d out of range), "
                  "everything frozen:\n",
                  s.log.c_str(), s.rows, counts[0], counts[1], counts[2]);
    out += b;
    for (const ModelScore& m : s.models) {
      if (m.points.empty()) continue;
      std::snprintf(b, sizeof b, "  %-13s point 1 RMS %.3f mm, max %.3f mm", (m.model + ":").c_str(),
                    m.points[0].rms_m * 1e3, m.points[0].max_m * 1e3);
      out += b;
      for (const auto& [g, p] : m.groups)
        if (!p.empty()) {
          std::snprintf(b, sizeof b, "; %s %.3f", Name(g), p[0].rms_m * 1e3);
          out += b;
        }
      if (m.points.size() > 1) {
        out += "; points";
        for (const auto& p : m.points) {
          std::snprintf(b, sizeof b, " %d: %.3f", p.point, p.rms_m * 1e3);
          out += b;
        }
        out += " mm RMS";
      }
      out += "\n";
    }
    out += MovedText(s);
  }
  return out;
}

nlohmann::json ValidationJson(const std::vector<SessionScore>& sessions) {
  nlohmann::json a = nlohmann::json::array();
  for (const SessionScore& s : sessions) {
    nlohmann::json models = nlohmann::json::array();
    for (const ModelScore& m : s.models) {
      nlohmann::json groups = nlohmann::json::object();
      for (const auto& [g, p] : m.groups) groups[Name(g)] = {{"rows", p.empty() ? 0 : p.front().rows}, {"points", PointsJson(p)}};
      models.push_back({{"model", m.model}, {"points", PointsJson(m.points)}, {"groups", groups}});
    }
    a.push_back({{"log", s.log}, {"rows", s.rows}, {"models", models}});
  }
  return a;
}

}  // namespace mcms
