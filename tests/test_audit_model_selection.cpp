// The selection rule of the model audit (audit/model_selection.h) on its own: a clear
// winner is named, nothing is named when the gains are within chance, two candidates
// that explain the same residual equally end as undecided, and on simulated clean
// likelihood ratios the rule's false-alarm rate is at most its alpha.
#include <gtest/gtest.h>

#include <cmath>

#include "core/random.h"
#include "audit/model_selection.h"

namespace mcms {
namespace {

SelectionCandidate Cand(int k, double lr, double heldout, int group = 0) {
  SelectionCandidate c;
  c.k = k;
  c.lr = lr;
  c.heldout_gain = heldout;
  c.group = group;
  return c;
}

SelectionRule Rule(double n = 1000) {
  SelectionRule r;
  r.alpha = 0.005;
  r.ln_n = std::log(n);
  return r;
}

TEST(ModelSelection, ChiSquareHelpers) {
  EXPECT_NEAR(ChiSquareSurvival(3.841458820694124, 1), 0.05, 1e-9);
  EXPECT_NEAR(ChiSquareThreshold(2, 0.01), -2 * std::log(0.01), 1e-9);
  EXPECT_EQ(ChiSquareSurvival(-1, 3), 1.0);
  EXPECT_EQ(TimeBlockFold(0, 10, 5), 0);
  EXPECT_EQ(TimeBlockFold(9, 10, 5), 4);
  EXPECT_EQ(TimeBlockFold(5, 10, 2), 1);
  EXPECT_TRUE(EarnsPlace(100, 2, 0.001, std::log(1000.0)));
  EXPECT_FALSE(EarnsPlace(10, 2, 0.001, std::log(1000.0)));
}

TEST(ModelSelection, AClearWinnerIsNamed) {
  std::vector<SelectionCandidate> c{Cand(2, 8.0, 0.5), Cand(1, 150.0, 60.0), Cand(3, 40.0, 5.0)};
  const StepDecision d = DecideStep(c, 3, Rule());
  EXPECT_EQ(d.outcome, StepOutcome::kNamed);
  EXPECT_EQ(d.best, 1);
  EXPECT_TRUE(c[1].passes);
  EXPECT_FALSE(c[0].passes);
  EXPECT_NEAR(c[1].bic_gain, 150.0 - std::log(1000.0), 1e-12);
}

TEST(ModelSelection, NothingWithinChance) {
  // Likelihood ratios of the size chance gives (below the Bonferroni threshold, BIC < 0).
  std::vector<SelectionCandidate> c{Cand(1, 6.0, 1.0), Cand(2, 9.0, 2.0), Cand(3, 11.0, 0.5)};
  EXPECT_EQ(DecideStep(c, 10, Rule()).outcome, StepOutcome::kNothingPasses);
  // Passes on all data but loses held out: not named either.
  std::vector<SelectionCandidate> h{Cand(1, 40.0, -2.0)};
  const StepDecision d = DecideStep(h, 1, Rule());
  EXPECT_EQ(d.outcome, StepOutcome::kNoHeldoutGain);
  EXPECT_EQ(d.best, 0);
}

TEST(ModelSelection, TheBonferroniShareGrowsWithTheCandidates) {
  // lr 12 with k = 1: p = 5.3e-4 < 0.005 / 5, but > 0.005 / 20.
  std::vector<SelectionCandidate> c{Cand(1, 12.0, 3.0)};
  EXPECT_EQ(DecideStep(c, 5, Rule(100)).outcome, StepOutcome::kNamed);
  EXPECT_EQ(DecideStep(c, 20, Rule(100)).outcome, StepOutcome::kNothingPasses);
  c[0].multiplicity = 9;  // a scan hidden in the candidate counts too
  EXPECT_EQ(DecideStep(c, 5, Rule(100)).outcome, StepOutcome::kNothingPasses);
}

TEST(ModelSelection, TwoEqualCandidatesAreUndecided) {
  std::vector<SelectionCandidate> c{Cand(2, 120.0, 50.0), Cand(2, 120.5, 50.3), Cand(1, 9.0, 0.1)};
  const StepDecision d = DecideStep(c, 3, Rule());
  ASSERT_EQ(d.outcome, StepOutcome::kUndecided);
  ASSERT_EQ(d.group.size(), 2u);
  EXPECT_EQ(d.group[0], 1);  // the larger held-out gain first
  EXPECT_EQ(d.group[1], 0);
  // The same two on different data (two cameras) are each taken in turn: no tie.
  c[0].group = 1;
  c[0].heldout_gain = c[1].heldout_gain = std::nan("");
  c[0].heldout_gain = 50.0;
  c[1].heldout_gain = 50.3;
  EXPECT_EQ(DecideStep(c, 3, Rule()).outcome, StepOutcome::kNamed);
}

TEST(ModelSelection, HeldOutDecidesBetweenCloseCandidatesAndIsAskedLazily) {
  // Two close in BIC: the one with the larger held-out gain wins (a drift against a
  // geometric error); the held-out gain of a far weaker one is never computed.
  std::vector<SelectionCandidate> c{Cand(1, 200.0, std::nan("")), Cand(1, 195.0, std::nan("")),
                                    Cand(1, 30.0, std::nan(""))};
  std::vector<int> asked;
  const StepDecision d = DecideStep(c, 3, Rule(), [&](int i) {
    asked.push_back(i);
    return i == 1 ? 40.0 : 10.0;
  });
  EXPECT_EQ(d.outcome, StepOutcome::kNamed);
  EXPECT_EQ(d.best, 1);
  EXPECT_EQ(asked, (std::vector<int>{0, 1}));
  // A simpler candidate that fits as well wins on BIC: the 6-parameter one is not a contender.
  std::vector<SelectionCandidate> s{Cand(6, 100.0, 41.0), Cand(2, 99.0, 40.0)};
  const StepDecision e = DecideStep(s, 2, Rule());
  EXPECT_EQ(e.outcome, StepOutcome::kNamed);
  EXPECT_EQ(e.best, 1);
}

TEST(ModelSelection, FalseAlarmRateOnCleanLikelihoodRatiosIsAtMostAlpha) {
  // Under the null each candidate's likelihood ratio is chi-square(k); 20000 clean steps
  // of 8 candidates (k = 1..3) with positive held-out gains (the worst case for the rule):
  // the rate of naming anything must not exceed alpha (Bonferroni), beyond chance.
  Rng rng(7);
  const SelectionRule r = Rule(200);
  int alarms = 0;
  const int steps = 20000;
  for (int s = 0; s < steps; ++s) {
    std::vector<SelectionCandidate> c;
    for (int i = 0; i < 8; ++i) {
      const int k = 1 + i % 3;
      double lr = 0;
      for (int j = 0; j < k; ++j) lr += std::pow(rng.Normal(), 2);
      c.push_back(Cand(k, lr, 1.0));
    }
    alarms += DecideStep(c, 8, r).outcome != StepOutcome::kNothingPasses;
  }
  const double rate = static_cast<double>(alarms) / steps;
  // alpha = 0.005: 100 expected at most; 3 sigma above a binomial's mean.
  EXPECT_LE(alarms, r.alpha * steps + 3 * std::sqrt(r.alpha * steps)) << rate;
  std::printf("clean steps: %d of %d named something (rate %.4f, designed <= %.4f)\n", alarms, steps, rate, r.alpha);
}

}  // namespace
}  // namespace mcms
