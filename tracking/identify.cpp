#include "tracking/identify.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace mcms {

bool IdentificationOptions::IsValid(std::string* why) const {
  if (!(distance_sigma_floor_m >= 0)) return (*why = "distance_sigma_floor_m must be >= 0", false);
  if (!(gate_sigma > 0)) return (*why = "gate_sigma must be positive", false);
  if (max_missing < 0) return (*why = "max_missing must be >= 0", false);
  return true;
}

Pose FitRigid(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  Vec3 ca = Vec3::Zero(), cb = Vec3::Zero();
  for (size_t i = 0; i < a.size(); ++i) {
    ca += a[i];
    cb += b[i];
  }
  ca /= a.size();
  cb /= b.size();
  Mat3 S = Mat3::Zero();
  for (size_t i = 0; i < a.size(); ++i) S += (b[i] - cb) * (a[i] - ca).transpose();
  Eigen::JacobiSVD<Mat3> svd(S, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) D(2, 2) = -1;
  Pose T;
  T.R = svd.matrixU() * D * svd.matrixV().transpose();
  T.t = cb - T.R * ca;
  return T;
}

namespace {

struct Search {
  const Target& target;
  const std::vector<TriangulatedPoint>& points;
  const IdentificationOptions& o;
  int nb, np;
  std::vector<int> assign;
  std::vector<bool> used;
  // Every complete assignment within `window` of the best so far; the runner-up is
  // chosen among them afterwards (it must conflict with the best, not just drop a ball).
  static constexpr double kWindow = 100.0;
  double best = std::numeric_limits<double>::infinity();
  std::vector<int> best_assign;
  std::vector<std::pair<double, std::vector<int>>> found;

  // Variance of the distance between points i and j along their separation.
  double DistanceVariance(int i, int j) const {
    const Vec3 u = (points[i].p_rig - points[j].p_rig).normalized();
    return u.dot((points[i].cov + points[j].cov) * u) + o.distance_sigma_floor_m * o.distance_sigma_floor_m;
  }

  void Recurse(int ball, double cost, int missing) {
    if (cost >= best + kWindow) return;
    if (ball == nb) {
      if (nb - missing < 3) return;
      found.emplace_back(cost, assign);
      if (cost < best) {
        best = cost;
        best_assign = assign;
      }
      return;
    }
    for (int p = 0; p < np; ++p) {
      if (used[p]) continue;
      double add = 0;
      bool ok = true;
      for (int b = 0; b < ball && ok; ++b) {
        if (assign[b] < 0) continue;
        const double d = (points[p].p_rig - points[assign[b]].p_rig).norm();
        const double D = (target.balls_target[ball] - target.balls_target[b]).norm();
        const double z2 = (d - D) * (d - D) / DistanceVariance(p, assign[b]);
        if (z2 > o.gate_sigma * o.gate_sigma) ok = false;
        add += z2;
      }
      if (!ok) continue;
      used[p] = true;
      assign[ball] = p;
      Recurse(ball + 1, cost + add, missing);
      used[p] = false;
      assign[ball] = -1;
    }
    if (missing < o.max_missing) Recurse(ball + 1, cost + o.missing_penalty, missing + 1);
  }
};

}  // namespace

std::optional<Identification> IdentifyTarget(const Target& target, const std::vector<TriangulatedPoint>& points,
                                             const IdentificationOptions& options) {
  Search s{target, points, options, static_cast<int>(target.balls_target.size()), static_cast<int>(points.size()),
           std::vector<int>(target.balls_target.size(), -1), std::vector<bool>(points.size(), false)};
  if (s.np < 3) return std::nullopt;
  s.Recurse(0, 0.0, 0);
  if (s.best_assign.empty()) return std::nullopt;
  Identification id;
  id.point_of_ball = s.best_assign;
  id.cost = s.best;
  // Runner-up: the best assignment that gives some ball another point, or some point
  // another ball (dropping a ball from the best one is not a competing identity).
  id.margin = std::numeric_limits<double>::infinity();
  for (const auto& [cost, assign] : s.found) {
    bool conflicts = false;
    for (int b = 0; b < s.nb && !conflicts; ++b) {
      if (assign[b] < 0) continue;
      for (int c = 0; c < s.nb; ++c)
        if (s.best_assign[c] == assign[b] && c != b) conflicts = true;
      if (s.best_assign[b] >= 0 && s.best_assign[b] != assign[b]) conflicts = true;
    }
    if (conflicts) id.margin = std::min(id.margin, cost - s.best);
  }
  std::vector<Vec3> a, b;
  for (int k = 0; k < s.nb; ++k)
    if (id.point_of_ball[k] >= 0) {
      a.push_back(target.balls_target[k]);
      b.push_back(points[id.point_of_ball[k]].p_rig);
      ++id.balls_found;
    }
  id.T_rig_target = FitRigid(a, b);
  double sq = 0;
  for (size_t i = 0; i < a.size(); ++i) sq += (id.T_rig_target * a[i] - b[i]).squaredNorm();
  id.fit_rms_m = std::sqrt(sq / a.size());
  return id;
}

}  // namespace mcms
