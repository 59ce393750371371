#include "fusion/consistency.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/statistics.h"
#include "fusion/gaussian_internal.h"
#include "fusion/moifa_internal.h"

namespace mcms {

using internal::Mat;
using internal::PseudoInverse;
using internal::Vec;

bool ConsistencyOptions::IsValid(std::string* why) const {
  if (significance > 0.0 && significance < 1.0) return true;
  if (why) {
    std::ostringstream s;
    s << "consistency options: significance must be in (0, 1), is " << significance;
    *why = s.str();
  }
  return false;
}

namespace {

template <int N>
struct Item {
  std::string name;
  Mat<N> L;  // information on the common tangent
  Vec<N> b;  // measured value on that tangent
  int rank;
};

struct Chi2 {
  double value;
  int dof;
};

// Minimum weighted residual of the members of `use` and its degrees of freedom.
template <int N>
Chi2 MinimumResidual(const std::vector<Item<N>>& items, const std::vector<bool>& use) {
  Mat<N> H = Mat<N>::Zero();
  Vec<N> g = Vec<N>::Zero();
  int ranks = 0;
  for (size_t i = 0; i < items.size(); ++i)
    if (use[i]) {
      H += items[i].L;
      g += items[i].L * items[i].b;
      ranks += items[i].rank;
    }
  int rank_H = 0;
  const Vec<N> x = PseudoInverse<N>(H, &rank_H) * g;  // a minimizer; the minimum is unique
  double chi2 = 0.0;
  for (size_t i = 0; i < items.size(); ++i)
    if (use[i]) {
      const Vec<N> r = x - items[i].b;
      chi2 += r.dot(items[i].L * r);
    }
  return {std::max(chi2, 0.0), ranks - rank_H};
}

template <int N>
void PerSensor(const std::vector<Item<N>>& items, const std::vector<bool>& use, const Chi2& total,
               double significance, std::vector<SensorConsistency>* out) {
  out->clear();
  for (size_t i = 0; i < items.size(); ++i) {
    SensorConsistency s;
    s.name = items[i].name;
    if (use[i]) {
      std::vector<bool> others = use;
      others[i] = false;
      const Chi2 rest = MinimumResidual<N>(items, others);
      s.dof = total.dof - rest.dof;
      s.nis = std::max(total.value - rest.value, 0.0);
      s.p_value = s.dof > 0 ? ChiSquareSurvival(s.nis, s.dof) : 1.0;
      s.flagged = s.p_value < significance;
    }
    out->push_back(s);
  }
}

template <int N>
ConsistencyReport Check(const std::vector<Item<N>>& items, const ConsistencyOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw(why);
  if (items.empty()) Throw("consistency check: no measurement given");
  ConsistencyReport report;
  std::vector<bool> use(items.size(), true);
  const Chi2 total = MinimumResidual<N>(items, use);
  report.chi2 = total.value;
  report.dof = total.dof;
  report.p_value = total.dof > 0 ? ChiSquareSurvival(total.value, total.dof) : 1.0;
  report.consistent = report.p_value >= options.significance;
  PerSensor<N>(items, use, total, options.significance, &report.sensors);

  // Greedy isolation.
  Chi2 current = total;
  std::vector<SensorConsistency> current_sensors = report.sensors;
  int remaining = static_cast<int>(items.size());
  while (true) {
    const double p = current.dof > 0 ? ChiSquareSurvival(current.value, current.dof) : 1.0;
    if (p >= options.significance) break;
    if (remaining <= 2) {
      report.attributed = false;
      break;
    }
    int worst = -1;
    for (size_t i = 0; i < items.size(); ++i)
      if (use[i] && current_sensors[i].dof > 0 &&
          (worst < 0 || current_sensors[i].p_value < current_sensors[worst].p_value))
        worst = static_cast<int>(i);
    if (worst < 0) {
      report.attributed = false;
      break;
    }
    use[worst] = false;
    --remaining;
    report.excluded.push_back(worst);
    current = MinimumResidual<N>(items, use);
    PerSensor<N>(items, use, current, options.significance, &current_sensors);
  }
  return report;
}

}  // namespace

ConsistencyReport CheckConsistency(const std::vector<PositionMeasurement>& measurements,
                                   const ConsistencyOptions& options) {
  std::vector<Item<3>> items;
  for (const auto& m : measurements) {
    int rank = 0;
    const Mat3 pinv = PseudoInverse<3>(m.information, &rank);
    items.push_back({m.name, m.information, pinv * m.information_vector, rank});
  }
  return Check<3>(items, options);
}

ConsistencyReport CheckConsistency(const std::vector<PoseMeasurement>& measurements,
                                   const ConsistencyOptions& options, const FusePosesOptions& fuse_options) {
  std::string why;
  if (!options.IsValid(&why)) Throw(why);
  const FusedPose fused = FusePoses(measurements, fuse_options);
  std::vector<Item<6>> items;
  for (const auto& m : measurements) {
    const internal::LinearizedPose lp = internal::Linearize(m, fused.T, true);
    items.push_back({m.name, lp.information, lp.value, internal::Rank<6>(lp.information)});
  }
  return Check<6>(items, options);
}

}  // namespace mcms
