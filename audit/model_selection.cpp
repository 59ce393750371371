#include "audit/model_selection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>


#include "core/error.h"

namespace mcms {

double Correlation(const std::vector<double>& x, const std::vector<double>& y) {
  const size_t n = std::min(x.size(), y.size());
  if (n < 3) return std::nan("");
  const double mx = std::accumulate(x.begin(), x.begin() + n, 0.0) / n;
  const double my = std::accumulate(y.begin(), y.begin() + n, 0.0) / n;
  double sxy = 0, sxx = 0, syy = 0;
  for (size_t i = 0; i < n; ++i) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
    syy += (y[i] - my) * (y[i] - my);
  }
  return sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : std::nan("");
}

AuditTest AutocorrelationTest(const std::string& name, const std::vector<double>& w) {
  double num = 0, den = 0;
  for (size_t i = 0; i < w.size(); ++i) {
    den += w[i] * w[i];
    if (i + 1 < w.size()) num += w[i] * w[i + 1];
  }
  const double r1 = den > 0 ? num / den : 0.0;
  return {name, r1, TwoSidedNormalP(r1 * std::sqrt(static_cast<double>(w.size()))), false};
}

std::optional<AuditTest> TrendTest(const std::string& name, const std::vector<double>& x, const std::vector<double>& w) {
  const double r = Correlation(x, w);
  if (!std::isfinite(r)) return std::nullopt;
  const double n = static_cast<double>(std::min(x.size(), w.size()));
  const double z = std::atanh(std::clamp(r, -0.999999, 0.999999)) * std::sqrt(std::max(1.0, n - 3.0));
  return AuditTest{name, r, TwoSidedNormalP(z), false};
}

bool EarnsPlace(double lr, double k, double alpha, double ln_n) {
  return ChiSquareSurvival(lr, k) < alpha && BicGain(lr, k, ln_n) > 0;
}

int TimeBlockFold(long i, long n, int folds) { return static_cast<int>(i * folds / std::max(1L, n)); }

bool SelectionRule::IsValid(std::string* why) const {
  const auto fail = [&](const char* w) {
    if (why) *why = w;
    return false;
  };
  if (!(alpha > 0 && alpha < 1)) return fail("alpha must be in (0, 1)");
  if (!(ln_n >= 0)) return fail("ln_n must be >= 0");
  if (!(close_bic >= 0) || !(undecided_heldout >= 0) || !(undecided_bic >= 0) || !(undecided_bic_relative >= 0))
    return fail("margins must be >= 0");
  if (!(tie_z >= 0)) return fail("tie_z must be >= 0");
  return true;
}

double PairedZ(const std::vector<double>& a, const std::vector<double>& b, double offset) {
  const size_t n = a.size();
  if (n == 0 || b.size() != n) return 0.0;
  double sum = 0, sq = 0;
  for (size_t i = 0; i < n; ++i) {
    const double d = a[i] - b[i];
    sum += d;
    sq += d * d;
  }
  const double var = std::max(0.0, sq / n - (sum / n) * (sum / n));
  const double se = std::sqrt(n * var);
  const double x = sum - offset;
  if (!(se > 0)) return x > 0 ? std::numeric_limits<double>::infinity() : (x < 0 ? -std::numeric_limits<double>::infinity() : 0.0);
  return x / se;
}

StepDecision DecideStep(std::vector<SelectionCandidate>& cands, int m, const SelectionRule& rule,
                        const std::function<double(int)>& heldout_gain) {
  std::string why;
  if (!rule.IsValid(&why)) Throw("selection rule: ", why);
  m = std::max<int>(m, static_cast<int>(cands.size()));
  std::vector<int> passing;
  for (size_t i = 0; i < cands.size(); ++i) {
    SelectionCandidate& c = cands[i];
    c.bic_gain = BicGain(c.lr, c.k, rule.ln_n);
    c.p_value = ChiSquareSurvival(c.lr, c.k);
    c.passes = c.k > 0 && c.p_value < rule.alpha / (m * std::max(1.0, c.multiplicity)) && c.bic_gain > 0;
    if (c.passes) passing.push_back(static_cast<int>(i));
  }
  StepDecision d;
  if (passing.empty()) return d;
  std::stable_sort(passing.begin(), passing.end(),
                   [&](int a, int b) { return cands[a].bic_gain > cands[b].bic_gain; });
  const auto Gain = [&](int i) {
    if (std::isnan(cands[i].heldout_gain)) {
      if (!heldout_gain) Throw("selection: held-out gain of candidate ", i, " unknown and no way to compute it");
      cands[i].heldout_gain = heldout_gain(i);
    }
    return cands[i].heldout_gain;
  };
  // The bar: the best BIC gain among the candidates that gain held-out.
  double bar = std::nan("");
  for (int i : passing)
    if (Gain(i) > 0) {
      bar = cands[i].bic_gain;
      break;
    }
  if (std::isnan(bar)) {
    d.outcome = StepOutcome::kNoHeldoutGain;
    d.best = passing.front();
    return d;
  }
  std::vector<int> contenders;
  for (int i : passing)
    if (cands[i].bic_gain >= bar - rule.close_bic && Gain(i) > 0) contenders.push_back(i);
  int best = contenders.front();
  for (int i : contenders)
    if (cands[i].heldout_gain > cands[best].heldout_gain) best = i;
  // Whether candidate i explains the same residual as `b` equally well (rule 4).
  const auto Ties = [&](int b, int i) {
    const SelectionCandidate &cb = cands[b], &ci = cands[i];
    const bool rows = !cb.row_loglik.empty() && cb.row_loglik.size() == ci.row_loglik.size();
    if (rows) {
      // Only a candidate that also gains held out can stand beside the best.
      if (!(Gain(i) > 0)) return false;
      if (PairedZ(cb.row_loglik, ci.row_loglik, 0.5 * (cb.k - ci.k) * rule.ln_n) < rule.tie_z) return true;
      const double h = ci.heldout_gain;
      if (!cb.heldout_row_loglik.empty() && cb.heldout_row_loglik.size() == ci.heldout_row_loglik.size())
        return PairedZ(cb.heldout_row_loglik, ci.heldout_row_loglik) < 1.0;
      return std::abs(h - cb.heldout_gain) <= rule.undecided_heldout;
    }
    if (!(ci.bic_gain >= bar - rule.close_bic)) return false;
    const double h = Gain(i);
    return std::abs(h - cb.heldout_gain) <= rule.undecided_heldout &&
           std::abs(ci.bic_gain - cb.bic_gain) <= rule.undecided_bic + rule.undecided_bic_relative * cb.lr;
  };
  const auto GroupOf = [&](int b) {
    std::vector<int> g{b};
    for (int i : passing) {
      if (i == b || cands[i].group != cands[b].group) continue;
      if (cands[i].tier > cands[b].tier) continue;  // rule 5
      if (Ties(b, i)) g.push_back(i);
    }
    return g;
  };
  std::vector<int> group = GroupOf(best);
  // Rule 5: a tied candidate of a lower tier is named in the best's place.
  for (int guard = 0; guard < 8; ++guard) {
    int lower = -1;
    for (int i : group)
      if (cands[i].tier < cands[best].tier &&
          (lower < 0 || cands[i].tier < cands[lower].tier ||
           (cands[i].tier == cands[lower].tier && cands[i].heldout_gain > cands[lower].heldout_gain)))
        lower = i;
    if (lower < 0) break;
    best = lower;
    group = GroupOf(best);
  }
  // The group holds only the best's tier.
  group.erase(std::remove_if(group.begin() + 1, group.end(), [&](int i) { return cands[i].tier != cands[best].tier; }),
              group.end());
  d.best = best;
  d.group = group;
  d.outcome = d.group.size() > 1 ? StepOutcome::kUndecided : StepOutcome::kNamed;
  return d;
}

}  // namespace mcms
