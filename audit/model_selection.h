// The selection rule of the model audit (issue 11), one for every mode (robot, cameras,
// fusion): which candidate extension of the catalog (model/extensions.h) earns its place
// in one greedy forward-selection step, and when two cannot be told apart.
//
// Each mode fits its candidates its own way (its own forward model and noise model) and
// hands the engine, per candidate: the number of parameters k it adds, its likelihood
// ratio on all data lr = 2 (loglik_with - loglik_without), the group of data it explains
// (candidates in different groups, e.g. two cameras, never tie), and its held-out
// log-likelihood gain (k-fold, folds = contiguous blocks of time, so drift cannot leak
// from the training blocks into the test block), computed when the engine asks for it.
//
// The rule of one step, with m candidates tested in it:
//  1. a candidate passes when its likelihood ratio exceeds the chi-square(k) quantile at
//     alpha / (m * multiplicity) (Bonferroni over the step's candidates, and over a scan
//     such as a change time; on a clean data set a step names something with probability
//     <= alpha) and its BIC gain lr - k ln(n) is > 0 (it must earn its parameters);
//  2. the passing candidates are taken by BIC gain, best first; held-out gains are asked
//     for in that order until one is > 0 (its BIC sets the bar) and then for every
//     passing candidate within `close_bic` of that bar (the contenders);
//  3. among the contenders with a positive held-out gain, the one with the largest
//     held-out gain is the step's effect (a drift and a geometric error fit all data
//     alike; blocks of time tell them apart);
//  4. a contender of the same group that explains the same residual equally well is a
//     tie: the step names neither and reports the group as undecided. With per-
//     measurement log-likelihoods (row_loglik, heldout_row_loglik, as the robot audit
//     gives) a tie is judged statistically: the two candidates' fits differ by less than
//     chance produces on all data (Vuong's paired test of the per-measurement log-
//     likelihood differences with the BIC correction for their sizes, z below `tie_z`),
//     or their held-out gains differ by less
//     than one standard error of the paired per-measurement differences; any passing
//     candidate of the group is tested. Without them: held-out gains within
//     `undecided_heldout` nats and BIC gains within undecided_bic + undecided_bic_relative
//     * lr of the best's;
//  5. candidates carry a preference tier for ties (lower is preferred): a flexible family
//     (a harmonic series that can follow many shapes, e.g. error motion of an articulated
//     arm's joint) or a broad one (every DH parameter at once) is named only where no
//     candidate of a lower tier ties with it: when the best ties with a lower-tier
//     candidate, that one is taken in its place (its own ties decide undecided), and a
//     higher-tier candidate never joins a lower-tier best's undecided group;
//  6. no passing candidate, or none with a held-out gain > 0: the selection stops.
// Designed false-alarm rate: a mode gives the selection a share alpha of its rate; with
// at most one false step per data set the probability of naming anything on a clean data
// set is <= alpha (held-out gain and BIC only lower it).
#pragma once

#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "audit/audit_report.h"
#include "core/statistics.h"

namespace mcms {

// BIC(without) - BIC(with) for a likelihood ratio lr, k added parameters, ln(n) for n
// measurements (> 0: the candidate earns its parameters).
inline double BicGain(double lr, double k, double ln_n) { return lr - k * ln_n; }
// Whether an effect still earns its place (backward pruning): lr passes the chi-square
// test at alpha and the BIC gain is > 0.
bool EarnsPlace(double lr, double k, double alpha, double ln_n);
// The fold (0..folds-1) of the i-th of n measurements in time order: contiguous blocks.
int TimeBlockFold(long i, long n, int folds);

// Residual tests of a nominal fit, one definition for every mode: whitened residuals w
// (i.i.d. N(0, 1) under the model, in time order) tested for lag-1 autocorrelation
// (z = r1 sqrt(n)) and for a trend against a covariate x (Pearson r, Fisher's z =
// atanh(r) sqrt(n - 3)); two-sided normal p-values. A mode compares each p with its share
// of the false-alarm rate (Bonferroni over its tests).
// Pearson correlation of x and y (same size); NaN when either is constant or n < 3.
double Correlation(const std::vector<double>& x, const std::vector<double>& y);
AuditTest AutocorrelationTest(const std::string& name, const std::vector<double>& w);
// nullopt when the covariate (or w) is constant: nothing to test.
std::optional<AuditTest> TrendTest(const std::string& name, const std::vector<double>& x, const std::vector<double>& w);

struct SelectionRule {
  double alpha = 0.005;        // the selection's share of the designed false-alarm rate, per step
  double ln_n = 0.0;           // ln(number of measurements) for BIC
  double close_bic = 10.0;     // contenders: BIC gain within this of the bar
  double undecided_heldout = 1.0;  // nats
  double undecided_bic = 2.0;
  double undecided_bic_relative = 0.0;
  // With per-measurement log-likelihoods: Vuong's z below this is a tie (one-sided 5 %:
  // the chance of preferring the wrong one of two candidates that differ by this much).
  double tie_z = 1.645;
  bool IsValid(std::string* why) const;
};

struct SelectionCandidate {
  int k = 0;               // parameters it adds
  double lr = 0.0;         // 2 (loglik_with - loglik_without), all data
  int group = 0;           // the data it explains; only candidates of one group tie
  double multiplicity = 1; // a scan hidden in the candidate (e.g. change times): Bonferroni
  // Held-out log-likelihood gain (nats, summed over the folds); NaN until known. The
  // engine fills it through the callback for the candidates it needs.
  double heldout_gain = std::numeric_limits<double>::quiet_NaN();
  // Optional, for statistical ties: the log-likelihood of each measurement under the
  // candidate's fit on all data, and of each held-out measurement under its fold's fit
  // (same measurements, same order, for every candidate of the step). The held-out one
  // may be filled by the held-out callback.
  std::vector<double> row_loglik, heldout_row_loglik;
  int tier = 0;  // preference in ties (rule 5): 0 = a single physical cause; higher = broader or flexible
  // Filled by the engine.
  double bic_gain = 0.0, p_value = 1.0;
  bool passes = false;  // likelihood-ratio test and BIC
};

enum class StepOutcome {
  kNothingPasses,   // no candidate passes the likelihood-ratio test with a positive BIC gain
  kNoHeldoutGain,   // some pass on all data, none gains held-out log-likelihood
  kNamed,           // `best` earns its place
  kUndecided,       // `group` (best first) explain the same residual equally well
};

struct StepDecision {
  StepOutcome outcome = StepOutcome::kNothingPasses;
  int best = -1;                // the best contender (for kNoHeldoutGain: the best by BIC)
  std::vector<int> group;       // kUndecided: indices, best first
};

// Vuong's statistic for a paired comparison of per-measurement log-likelihoods a - b:
// (sum - offset) / sqrt(n var), where offset corrects for the models' sizes (Vuong 1989:
// (k_a - k_b) ln(n) / 2, the BIC correction; 0 for held-out log-likelihoods); +-inf when
// every difference is equal, 0 when a or b is empty or the sizes differ.
double PairedZ(const std::vector<double>& a, const std::vector<double>& b, double offset = 0.0);

// One step of greedy forward selection over `cands` (m candidates tested in the step,
// m >= cands.size(): candidates screened out before a full fit count). `heldout_gain(i)`
// returns candidate i's held-out gain; it is called only for candidates whose gain is NaN
// and that the rule needs (may be empty when every gain is given).
StepDecision DecideStep(std::vector<SelectionCandidate>& cands, int m, const SelectionRule& rule,
                        const std::function<double(int)>& heldout_gain = {});

}  // namespace mcms
