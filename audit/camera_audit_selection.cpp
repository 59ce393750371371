#include "audit/camera_audit_selection.h"

#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numeric>
#include <set>

#include <ceres/ceres.h>

#include "core/error.h"
#include "core/statistics.h"
#include "audit/model_selection.h"
#include "tracking/pose_refinement.h"
#include "vision/blob_detector.h"
#include "vision/sphere_projection.h"
#include "vision/triangulation.h"

namespace mcms::camera_audit {


// The residual tests of a model (terms, per-camera noise scales) on the leave-one-out
// residuals the auditor holds: each camera's chi-square, allowing the noise tolerance,
// two-sided (a noise model too pessimistic is also wrong), at alpha / (4 cameras); and each
// camera's whitened residuals (u, v) against time (lag-1 autocorrelation, trend), the
// position in the view (u, v, distance from the image centre) and the distance to the
// camera, Bonferroni over their number at alpha / 4: an effect the catalog lacks shows
// here first. All tests into *tests (the residual tests sorted by p), a line for the notes
// into *note, the whitened residuals into *residuals (optional); returns the number of
// scalar residuals and their chi-square (*chi2_total).
long TestModel(const Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
               const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
               std::vector<AuditTest>* tests_out, std::string* note, std::vector<std::string>* unaudited,
               double* chi2_total, std::vector<std::vector<WhitenedResidual>>* residuals) {
  const int nc = static_cast<int>(rig.size());
  long n_total = 0;
  *chi2_total = 0;
  const double tol2 = (1 + options.noise_tolerance) * (1 + options.noise_tolerance);
  for (int c = 0; c < nc; ++c) {
    const Eval e = a.Evaluate(a.CameraSamples(c), terms, scale, -1, false);
    n_total += 2 * e.n;
    *chi2_total += e.chi2;
    if (e.n == 0) {
      unaudited->push_back(rig.names[c] + ": no ball image predicted from the other cameras; not audited");
      continue;
    }
    const double dof = 2.0 * e.n;
    const double p_hi = ChiSquareSurvival(e.chi2 / tol2, dof);
    const double p_lo = ChiSquareCdf(e.chi2 * tol2, dof);
    const double p = std::min(1.0, 2 * std::min(p_hi, p_lo));
    tests_out->push_back({"chi-square of " + rig.names[c] + "'s leave-one-out residuals (chi2/dof, noise tolerance " +
                              std::to_string(static_cast<int>(std::lround(100 * options.noise_tolerance))) + " %)",
                          e.chi2 / dof, p, p < options.false_alarm / (4.0 * nc)});
  }
  std::vector<AuditTest> tests;
  for (int c = 0; c < nc; ++c) {
    if (a.CameraSamples(c).empty()) continue;
    const std::vector<WhitenedResidual> rs = a.Whitened(a.CameraSamples(c), terms, scale);
    std::vector<double> cov[5];
    const char* cov_name[5] = {"time", "image u", "image v", "distance from the image centre", "distance to the camera"};
    for (const auto& r : rs) {
      cov[0].push_back(r.time_s);
      cov[1].push_back(r.q.x());
      cov[2].push_back(r.q.y());
      cov[3].push_back(r.radius_px);
      cov[4].push_back(r.range_m);
    }
    for (int k = 0; k < 2; ++k) {
      std::vector<double> w;
      for (const auto& r : rs) w.push_back(r.w[k]);
      const std::string comp = k == 0 ? "u" : "v";
      tests.push_back(AutocorrelationTest(rig.names[c] + ": autocorrelation in time (" + comp + ")", w));
      for (int j = 0; j < 5; ++j)
        if (auto t = TrendTest(rig.names[c] + ": trend vs " + cov_name[j] + " (" + comp + ")", cov[j], w))
          tests.push_back(*t);
    }
    if (residuals) (*residuals)[c] = rs;
  }
  const double per = options.false_alarm / 4 / std::max<size_t>(1, tests.size());
  for (auto& t : tests) t.failed = t.p_value < per;
  std::stable_sort(tests.begin(), tests.end(),
                   [](const AuditTest& x, const AuditTest& y) { return x.p_value < y.p_value; });
  tests_out->insert(tests_out->end(), tests.begin(), tests.end());
  char b[200];
  std::snprintf(b, sizeof b, "%zu residual tests against time, the position in the view and the distance (each at %.3g)",
                tests.size(), per);
  *note = b;
  return n_total;
}

// The nominal model's tests, into res->report.tests (the failed ones and the three
// strongest residual tests besides) and res->residuals; returns the number of scalar
// residuals.
long TestNominalModel(Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
                      const std::vector<CameraModelTerm>& terms, CameraAuditResult* res_out) {
  CameraAuditResult& res = *res_out;
  AuditReport& rep = res.report;
  const int nc = static_cast<int>(rig.size());
  std::vector<AuditTest> tests;
  std::string note;
  double chi2_total = 0;
  const long n_total = TestModel(a, rig, options, terms, std::vector<double>(nc, 1.0), &tests, &note, &rep.notes,
                                 &chi2_total, &res.residuals);
  int shown = 0;
  for (const auto& t : tests)
    if (t.failed || t.name.rfind("chi-square", 0) == 0 || shown++ < 3) rep.tests.push_back(t);
  rep.notes.push_back(note);
  rep.nominal_n = n_total;
  rep.nominal_chi2_per_dof = n_total > 0 ? chi2_total / n_total : 0.0;
  if (n_total == 0) Throw("audit cameras: no ball image could be predicted from the other cameras");
  return n_total;
}

// The noise model first: each camera's scale, fitted within the tolerance band.
void FitNoiseScales(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options,
                    const std::vector<CameraModelTerm>& terms, std::vector<double>* scale_out, AuditReport* rep_out) {
  std::vector<double>& scale = *scale_out;
  AuditReport& rep = *rep_out;
  const int nc = static_cast<int>(rig.size());
  for (int c = 0; c < nc; ++c) {
    const auto& s = a.CameraSamples(c);
    if (s.empty()) continue;
    scale[c] = a.Fit(s, c, terms, {}, scale, ScaleMode::kBand, -1).scale;
    const UnitFit f = a.Fit(s, c, terms, {}, scale, ScaleMode::kFree, -1);
    std::vector<double> sc = scale;
    sc[c] = f.scale;
    const double lr = 2 * (a.Evaluate(s, terms, sc, -1, false).ll - a.Evaluate(s, terms, scale, -1, false).ll);
    rep.tests.push_back({"pixel noise scale of " + rig.names[c] + " (estimated factor on sigma; p against the band)",
                         f.scale, ChiSquareSurvival(lr, 1),
                         ChiSquareSurvival(lr, 1) < options.false_alarm / (2.0 * (7 * nc + nb))});
  }

}

// The indices of the terms of one unit (a camera: every effect but target_geometry at it;
// a ball: its target_geometry).
std::vector<int> UnitTerms(const std::vector<CameraModelTerm>& terms, bool cam_unit, int u) {
  std::vector<int> f;
  for (size_t k = 0; k < terms.size(); ++k)
    if ((terms[k].extension.effect != Effect::kTargetGeometry) == cam_unit && terms[k].extension.index == u)
      f.push_back(static_cast<int>(k));
  return f;
}

// How a unit's fit treats the camera's noise scale: free once named, else within the band;
// a ball unit has none.
ScaleMode UnitScaleMode(bool cam_unit, int u, const std::vector<bool>& noise_named) {
  if (!cam_unit) return ScaleMode::kFixed;
  return noise_named[u] ? ScaleMode::kFree : ScaleMode::kBand;
}

// Held-out evaluation of a unit's model (the terms `free` of `terms` fitted): each fold of
// time fitted on the others and evaluated on it, summed over the folds.
Eval CameraHeldOut(const Auditor& a, const CameraAuditOptions& options, bool cam_unit, int u,
             const std::vector<CameraModelTerm>& terms, const std::vector<int>& free, const std::vector<double>& scale,
             ScaleMode mode) {
  const auto& s = cam_unit ? a.CameraSamples(u) : a.BallSamples(u);
  Eval out;
  for (int f = 0; f < options.folds; ++f) {
    const UnitFit fit = a.Fit(s, cam_unit ? u : -1, terms, free, scale, mode, f);
    std::vector<double> sc = scale;
    if (cam_unit) sc[u] = fit.scale;
    const Eval e = a.Evaluate(s, fit.terms, sc, f, true);
    out.ll += e.ll;
    out.sq += e.sq;
    out.n += e.n;
  }
  return out;
}

// The candidates of one selection round, each fitted on all data and on the folds, with
// its likelihood ratio and held-out gain against its unit's current model; *tested
// receives the number of single candidates (the pairs fitted count on top of it).
std::vector<Candidate> RoundCandidates(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options,
                                       const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
                                       const std::set<std::pair<bool, int>>& blocked,
                                       const std::vector<bool>& noise_named, int* tested) {
  const int nc = static_cast<int>(rig.size());
  // The candidates.
  std::vector<Candidate> cands, pairs;
  auto has = [&](Effect e, int idx) {
    for (const auto& t : terms)
      if (t.extension.effect == e && t.extension.index == idx) return true;
    return false;
  };
  for (int c = 0; c < nc; ++c) {
    if (blocked.count({true, c}) || a.CameraSamples(c).empty()) continue;
    for (Effect e : {Effect::kPixelNoiseScale, Effect::kCameraMoved, Effect::kFocalLength, Effect::kPrincipalPoint,
                     Effect::kRadialDistortion, Effect::kCameraTimeOffset}) {
      if (has(e, c)) continue;
      if (e == Effect::kRadialDistortion && !HasK1(rig.cameras[c])) continue;
      Candidate x;
      x.term.extension = Extension{e, c, 0};
      x.term.parameters = x.term.extension.InitialParameters();
      x.unit = c;
      x.k = x.term.extension.NumParameters();
      cands.push_back(x);
      if (e == Effect::kCameraMoved && options.change_points > 0) {
        x.k += 1;
        x.step = true;  // the change time is scanned below
        cands.push_back(x);
      }
    }
    // Two effects of the camera's own at once: a camera whose focal length and principal
    // point (or any two of these) are both off is fitted by a 6-parameter move better than
    // by either alone; the pair, with fewer parameters than the move, is its own candidate.
    // A moved camera that is also late: a principal point and a time offset otherwise fit
    // it better than the move alone (a move with a principal point or a focal length is
    // not a pair: the move takes them up).
    const Effect own[] = {Effect::kCameraMoved, Effect::kFocalLength, Effect::kPrincipalPoint,
                          Effect::kRadialDistortion, Effect::kCameraTimeOffset};
    for (size_t i = 0; i < 5; ++i)
      for (size_t j = i + 1; j < 5; ++j) {
        const Effect e1 = own[i], e2 = own[j];
        if (e1 == Effect::kCameraMoved && e2 != Effect::kCameraTimeOffset) continue;
        if (has(e1, c) || has(e2, c)) continue;
        if ((e1 == Effect::kRadialDistortion || e2 == Effect::kRadialDistortion) && !HasK1(rig.cameras[c])) continue;
        Candidate x;
        x.term.extension = Extension{e1, c, 0};
        x.term.parameters = x.term.extension.InitialParameters();
        x.term2.extension = Extension{e2, c, 0};
        x.term2.parameters = x.term2.extension.InitialParameters();
        x.pair = true;
        x.unit = c;
        x.k = x.term.extension.NumParameters() + x.term2.extension.NumParameters();
        pairs.push_back(x);
      }
  }
  for (int b = 0; b < nb; ++b) {
    if (blocked.count({false, b}) || has(Effect::kTargetGeometry, b) || a.BallSamples(b).empty()) continue;
    Candidate x;
    x.term.extension = Extension{Effect::kTargetGeometry, b, 0};
    x.term.parameters = x.term.extension.InitialParameters();
    x.camera_unit = false;
    x.unit = b;
    x.k = 3;
    cands.push_back(x);
  }
  *tested = static_cast<int>(cands.size());
  if (cands.empty()) return cands;

  // The current model of each unit, fitted on all data and on each fold, once.
  auto unit_free = [&](bool cam_unit, int u) { return UnitTerms(terms, cam_unit, u); };
  auto mode_of = [&](bool cam_unit, int u) { return UnitScaleMode(cam_unit, u, noise_named); };
  // Held-out evaluation of a unit model `t_all` with its free terms `free`: sum over folds.
  auto heldout = [&](bool cam_unit, int u, const std::vector<CameraModelTerm>& t0, const std::vector<int>& free,
                     ScaleMode mode, double* ll, double* sq, long* n) {
    const Eval e = CameraHeldOut(a, options, cam_unit, u, t0, free, scale, mode);
    *ll = e.ll;
    *sq = e.sq;
    *n = e.n;
  };
  struct Base {
    double ll_all = 0, ll_held = 0, sq_held = 0;
    long n_held = 0;
  };
  std::map<std::pair<bool, int>, Base> base;
  for (const auto& x : cands) {
    const auto key = std::make_pair(x.camera_unit, x.unit);
    if (base.count(key)) continue;
    Base bs;
    const auto& s = x.camera_unit ? a.CameraSamples(x.unit) : a.BallSamples(x.unit);
    const auto free = unit_free(x.camera_unit, x.unit);
    const UnitFit fit = a.Fit(s, x.camera_unit ? x.unit : -1, terms, free, scale, mode_of(x.camera_unit, x.unit), -1);
    std::vector<double> sc = scale;
    if (x.camera_unit) sc[x.unit] = fit.scale;
    bs.ll_all = a.Evaluate(s, fit.terms, sc, -1, false).ll;
    heldout(x.camera_unit, x.unit, terms, free, mode_of(x.camera_unit, x.unit), &bs.ll_held, &bs.sq_held,
            &bs.n_held);
    base[key] = bs;
  }

  auto fit_candidate = [&](Candidate& x) {
    const auto& s = x.camera_unit ? a.CameraSamples(x.unit) : a.BallSamples(x.unit);
    std::vector<CameraModelTerm> t = terms;
    std::vector<int> free = unit_free(x.camera_unit, x.unit);
    t.push_back(x.term);
    free.push_back(static_cast<int>(t.size()) - 1);
    if (x.pair) {
      t.push_back(x.term2);
      free.push_back(static_cast<int>(t.size()) - 1);
    }
    const bool noise = x.term.extension.effect == Effect::kPixelNoiseScale;
    const ScaleMode mode = noise ? ScaleMode::kFree : mode_of(x.camera_unit, x.unit);
    const int cu = x.camera_unit ? x.unit : -1;
    // A part-way move: the change time that fits all data best, among the candidates.
    if (x.step) {
      std::vector<double> times;
      for (const auto& smp : s.s) times.push_back(smp.t);
      std::sort(times.begin(), times.end());
      times.erase(std::unique(times.begin(), times.end()), times.end());
      double best_ll = -std::numeric_limits<double>::infinity(), best_t = 0;
      for (int g = 1; g <= options.change_points; ++g) {
        const double tc = times[times.size() * g / (options.change_points + 1)];
        t.back().from_time_s = tc;
        const UnitFit fit = a.Fit(s, cu, t, free, scale, mode, -1);
        std::vector<double> sc = scale;
        if (cu >= 0) sc[cu] = fit.scale;
        const double ll = a.Evaluate(s, fit.terms, sc, -1, false).ll;
        if (ll > best_ll) {
          best_ll = ll;
          best_t = tc;
        }
      }
      t.back().from_time_s = best_t;
      x.term.from_time_s = best_t;
    }
    Eigen::VectorXd par_sigma;
    const UnitFit fit = a.Fit(s, cu, t, free, scale, mode, -1, &par_sigma);
    std::vector<double> sc = scale;
    if (cu >= 0) sc[cu] = fit.scale;
    const Base& bs = base[{x.camera_unit, x.unit}];
    const double ll_all = a.Evaluate(s, fit.terms, sc, -1, false).ll;
    x.lr = 2 * (ll_all - bs.ll_all);
    x.base_ll = bs.ll_all;
    double ll_h, sq_h;
    long n_h;
    heldout(x.camera_unit, x.unit, t, free, mode, &ll_h, &sq_h, &n_h);
    x.heldout_gain = ll_h - bs.ll_held;
    x.rms_before = bs.n_held > 0 ? std::sqrt(bs.sq_held / bs.n_held) : 0;
    x.rms_after = n_h > 0 ? std::sqrt(sq_h / n_h) : 0;
    x.fitted = fit.terms;
    x.scale = fit.scale;
    x.term = fit.terms[fit.terms.size() - (x.pair ? 2 : 1)];
    if (x.pair) x.term2 = fit.terms.back();
    if (noise) {
      // s from a sample variance: sd(s) = s / sqrt(2 n) for n residuals.
      x.sigma = {fit.scale / std::sqrt(4.0 * s.size())};
    } else {
      // The candidate's blocks are the last fitted.
      const int np = x.term.extension.NumParameters() + (x.pair ? x.term2.extension.NumParameters() : 0);
      for (int i = 0; i < np; ++i) {
        const int j = static_cast<int>(par_sigma.size()) - np + i;
        x.sigma.push_back(j >= 0 ? par_sigma[j] : std::nan(""));
      }
    }
    x.label = x.term.extension.Label(rig.names);
    if (x.pair) x.label = std::string(Name(x.term.extension.effect)) + " + " + x.term2.extension.Label(rig.names);
    if (x.step)
      x.label += " from t = " + std::to_string(x.term.from_time_s) + " s";
  };
  for (auto& x : cands) fit_candidate(x);
  // Pairs are fitted only at cameras where a single candidate passes its test (the others
  // have no residual two effects could explain). On a clean recording a pair is therefore
  // tested only after a single candidate passed, which happens at the designed rate: the
  // gate keeps the family-wise rate, and the pairs fitted count in the round's m.
  std::set<int> residual_at;
  for (const auto& x : cands)
    if (x.camera_unit && ChiSquareSurvival(x.lr, x.k) < options.false_alarm / 2 / *tested) residual_at.insert(x.unit);
  for (auto& x : pairs)
    if (residual_at.count(x.unit)) {
      fit_candidate(x);
      cands.push_back(x);
    }
  return cands;
}

// The units (cameras, balls) that carry terms.
std::set<std::pair<bool, int>> TermUnits(const std::vector<CameraModelTerm>& terms) {
  std::set<std::pair<bool, int>> units;
  for (const auto& t : terms) units.insert({t.extension.effect != Effect::kTargetGeometry, t.extension.index});
  return units;
}

// One unit's terms fitted on all its samples, written back with the camera's noise scale;
// returns the indices of the unit's terms (*sigma, optional: their parameters' sigmas, in order).
std::vector<int> RefitUnit(const Auditor& a, const std::vector<bool>& noise_named, bool cam_unit, int u,
                           std::vector<CameraModelTerm>* terms, std::vector<double>* scale,
                           Eigen::VectorXd* sigma = nullptr) {
  const std::vector<int> free = UnitTerms(*terms, cam_unit, u);
  const auto& s = cam_unit ? a.CameraSamples(u) : a.BallSamples(u);
  const UnitFit fit = a.Fit(s, cam_unit ? u : -1, *terms, free, *scale, UnitScaleMode(cam_unit, u, noise_named), -1, sigma);
  for (int k : free) (*terms)[k].parameters = fit.terms[k].parameters;
  if (cam_unit) (*scale)[u] = fit.scale;
  return free;
}

// After an effect is taken: every unit's terms fitted again on the poses re-fitted with
// it, and the poses again, until the cameras' leave-one-out log-likelihood gains less than
// half a nat in a sweep (at most `iterations` sweeps: two moved cameras pull each other's
// poses, and the sweeps converge by a constant factor each). A term fitted while another camera's fault
// was still unmodelled carries that fault's pull on the leave-one-out poses; once the
// fault is in the model the pull is gone, and the term must be fitted without it, or its
// stale part is charged to the next round's candidates elsewhere.
void RefitUnits(Auditor& a, const std::vector<bool>& noise_named, int iterations,
                std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out) {
  std::vector<CameraModelTerm>& terms = *terms_out;
  std::vector<double>& scale = *scale_out;
  double last = -std::numeric_limits<double>::infinity();
  for (int it = 0; it < iterations; ++it) {
    for (const auto& [cam_unit, u] : TermUnits(terms))
      if (!(cam_unit ? a.CameraSamples(u) : a.BallSamples(u)).empty()) RefitUnit(a, noise_named, cam_unit, u, &terms, &scale);
    a.Rebuild(terms, scale);
    double ll = 0;
    for (int c = 0; c < static_cast<int>(scale.size()); ++c) ll += a.Evaluate(a.CameraSamples(c), terms, scale, -1, false).ll;
    if (std::abs(ll - last) < 0.5) break;
    last = ll;
  }
}

// Backward pruning: an effect named early (e.g. the noise scale, taking up the residual of
// a large effect named later) must still earn its place once the others are in: each
// named effect is removed in turn when the likelihood ratio for it, on the poses
// re-fitted with every effect, no longer passes the test or its BIC gain is <= 0.
void PruneNamedEffects(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options, double ln_n,
                       std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out,
                       std::vector<bool>* noise_named_out, AuditReport* rep_out) {
  std::vector<CameraModelTerm>& terms = *terms_out;
  std::vector<double>& scale = *scale_out;
  std::vector<bool>& noise_named = *noise_named_out;
  AuditReport& rep = *rep_out;
  const int nc = static_cast<int>(rig.size());
  for (bool changed = true; changed;) {
    changed = false;
    for (size_t k = terms.size(); k-- > 0;) {
      if (terms[k].undecided) continue;
      const Extension x = terms[k].extension;
      const bool cam_unit = x.effect != Effect::kTargetGeometry;
      const auto& s = cam_unit ? a.CameraSamples(x.index) : a.BallSamples(x.index);
      std::vector<CameraModelTerm> without = terms;
      without.erase(without.begin() + static_cast<long>(k));
      auto free_of = [&](const std::vector<CameraModelTerm>& t) { return UnitTerms(t, cam_unit, x.index); };
      const bool noise = x.effect == Effect::kPixelNoiseScale;
      const ScaleMode with_mode = UnitScaleMode(cam_unit, x.index, noise_named);
      const ScaleMode without_mode = noise ? ScaleMode::kBand : with_mode;
      const UnitFit f1 = a.Fit(s, cam_unit ? x.index : -1, terms, free_of(terms), scale, with_mode, -1);
      const UnitFit f0 = a.Fit(s, cam_unit ? x.index : -1, without, free_of(without), scale, without_mode, -1);
      std::vector<double> s1 = scale, s0 = scale;
      if (cam_unit) s1[x.index] = f1.scale, s0[x.index] = f0.scale;
      const double lr = 2 * (a.Evaluate(s, f1.terms, s1, -1, false).ll - a.Evaluate(s, f0.terms, s0, -1, false).ll);
      const int kp = x.NumParameters() + (terms[k].from_time_s > -std::numeric_limits<double>::infinity() ? 1 : 0);
      const double m = static_cast<double>(nc * 7 + nb);
      if (EarnsPlace(lr, kp, options.false_alarm / (2 * m), ln_n)) continue;
      const std::string label = x.Label(rig.names);
      rep.notes.push_back(label + " was named, then no longer earned its place once the other effects were in " +
                          "(likelihood ratio " + std::to_string(lr) + "): removed");
      for (size_t e = 0; e < rep.effects.size(); ++e)
        if (rep.effects[e].name == Name(x.effect) && rep.effects[e].where == x.Where(rig.names)) {
          rep.effects.erase(rep.effects.begin() + static_cast<long>(e));
          break;
        }
      if (noise) noise_named[x.index] = false;
      terms = f0.terms;
      if (cam_unit) scale[x.index] = f0.scale;
      a.Rebuild(terms, scale);
      changed = true;
      break;
    }
  }
}

// The report's named effect `name` at `where` taken out (it joins an undecided group).
void Unname(const std::string& name, const std::string& where, AuditReport* rep) {
  auto& ef = rep->effects;
  ef.erase(std::remove_if(ef.begin(), ef.end(), [&](const AuditEffect& e) { return e.name == name && e.where == where; }),
           ef.end());
}

// A move named while another camera's fault was still unmodelled may have won by what its
// six parameters took of that fault through the shared poses (a 3-camera rig: a focal length
// of one camera and a k1 of another; the move, a shift along the axis, took the focal
// length's place). Once every effect is in, each named move for the whole recording is
// judged again against its camera's simpler intrinsic explanations (focal length, principal
// point, both), each fitted in its place with every other term and the poses (the joint
// fit): where the move's extra parameters are no evidence against one of them (its
// likelihood ratio over it below the chi-square quantile at the recording's false-alarm
// rate itself, without the candidates' Bonferroni: the move keeps its place on any evidence
// that it is one), the one of these with the best BIC that earns its own place (the test,
// BIC and a held-out gain, as the move did) is named instead, with a note.
void SimplifyNamedMoves(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options, double ln_n,
                        const std::vector<double>& scale, const std::vector<bool>& noise_named,
                        std::vector<CameraModelTerm>* terms_io, AuditReport* rep) {
  std::vector<CameraModelTerm>& terms = *terms_io;
  const double m = static_cast<double>(static_cast<int>(rig.size()) * 7 + nb);  // as the pruning's
  for (size_t k = 0; k < terms.size(); ++k) {
    const Extension x = terms[k].extension;
    if (terms[k].undecided || x.effect != Effect::kCameraMoved ||
        terms[k].from_time_s > -std::numeric_limits<double>::infinity())
      continue;
    auto has = [&](Effect e) {
      for (const auto& t : terms)
        if (t.extension.effect == e && t.extension.index == x.index) return true;
      return false;
    };
    std::vector<CameraModelTerm> with = terms;
    const double ll_move = a.JointFit(&with, scale);
    std::vector<CameraModelTerm> without = terms;
    without.erase(without.begin() + static_cast<long>(k));
    std::vector<CameraModelTerm> none = without;
    const double ll_none = a.JointFit(&none, scale);
    std::vector<CameraModelTerm> best;
    double best_bic = -std::numeric_limits<double>::infinity(), best_ll = 0, best_lr = 0;
    int best_k = 0;
    for (const std::vector<Effect>& r : std::vector<std::vector<Effect>>{
             {Effect::kFocalLength}, {Effect::kPrincipalPoint}, {Effect::kFocalLength, Effect::kPrincipalPoint}}) {
      bool taken = false;
      int kr = 0;
      std::vector<CameraModelTerm> t = without;
      for (Effect e : r) {
        taken = taken || has(e);
        CameraModelTerm term;
        term.extension = Extension{e, x.index, 0};
        term.parameters = term.extension.InitialParameters();
        kr += term.extension.NumParameters();
        t.push_back(term);
      }
      if (taken) continue;
      const double ll = a.JointFit(&t, scale);
      const double lr = 2 * (ll_move - ll);
      // Among those the move does not beat and that earn their own place as the move did
      // (the candidates' test and BIC), the one of the best BIC (a principal point must earn
      // its two parameters beside a focal length).
      const double bic = 2 * ll - kr * ln_n;
      if (ChiSquareSurvival(lr, x.NumParameters() - kr) < options.false_alarm ||
          !EarnsPlace(2 * (ll - ll_none), kr, options.false_alarm / (2 * m), ln_n) || bic <= best_bic)
        continue;
      best = t;
      best_bic = bic;
      best_ll = ll;
      best_lr = lr;
      best_k = kr;
    }
    if (best.empty()) continue;
    // Named in the move's place: its held-out figures on its camera's samples against the
    // camera without the move, the poses re-fitted without it.
    const std::string move_label = x.Label(rig.names);
    a.Rebuild(without, scale);
    const ScaleMode mode = UnitScaleMode(true, x.index, noise_named);
    const Eval h0 = CameraHeldOut(a, options, true, x.index, without, UnitTerms(without, true, x.index), scale, mode);
    const Eval h1 = CameraHeldOut(a, options, true, x.index, best, UnitTerms(best, true, x.index), scale, mode);
    if (!(h1.ll > h0.ll)) {  // no held-out gain of its own: the move stays
      a.Rebuild(terms, scale);
      continue;
    }
    // In the report's order, where the move was.
    auto at = std::find_if(rep->effects.begin(), rep->effects.end(), [&](const AuditEffect& e) {
      return e.name == Name(x.effect) && e.where == x.Where(rig.names);
    });
    if (at != rep->effects.end()) at = rep->effects.erase(at);
    std::string named;
    for (size_t j = without.size(); j < best.size(); ++j) {
      const Extension& y = best[j].extension;
      AuditEffect ef;
      ef.name = Name(y.effect);
      ef.where = y.Where(rig.names);
      for (const std::string& p : y.ParameterNames()) {
        ef.parameters.push_back({p, 0.0});
        ef.sigma.push_back({p, std::nan("")});
      }
      ef.heldout_rms_before = h0.n > 0 ? std::sqrt(h0.sq / h0.n) : 0;
      ef.heldout_rms_after = h1.n > 0 ? std::sqrt(h1.sq / h1.n) : 0;
      ef.heldout_loglik_gain = h1.ll - h0.ll;
      ef.bic_gain = BicGain(2 * (best_ll - ll_none), best_k, ln_n);
      at = rep->effects.insert(at, ef) + 1;
      named += (named.empty() ? "" : " + ") + y.Label(rig.names);
    }
    char lr[32];
    std::snprintf(lr, sizeof lr, "%.1f", best_lr);
    rep->notes.push_back(move_label + " was selected, but once the other effects were in, " + named +
                         " explains the images as well with " + std::to_string(x.NumParameters() - best_k) +
                         " fewer parameters (the move's likelihood ratio over it " + lr +
                         ", no evidence of a move at the false-alarm rate): named in the move's place");
    terms = best;
    a.Rebuild(terms, scale);
    k = static_cast<size_t>(-1);  // the terms changed: judge the remaining moves afresh
  }
}

// A last fit of every unit with named effects on the poses re-fitted with all of them
// (the noise scale, in particular, whitens with the pose covariances of its own value).
void RefitNamedUnits(Auditor& a, const CameraRig& rig, const std::vector<bool>& noise_named,
                     std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out, AuditReport* rep_out) {
  std::vector<CameraModelTerm>& terms = *terms_out;
  std::vector<double>& scale = *scale_out;
  AuditReport& rep = *rep_out;
  for (const auto& [cam_unit, u] : TermUnits(terms)) {
    const auto& s = cam_unit ? a.CameraSamples(u) : a.BallSamples(u);
    Eigen::VectorXd par_sigma;
    const std::vector<int> free = RefitUnit(a, noise_named, cam_unit, u, &terms, &scale, &par_sigma);
    int j = 0;
    for (int k : free) {
      const Extension& x = terms[k].extension;
      std::vector<double> sg;
      if (x.effect == Effect::kPixelNoiseScale) {
        sg.push_back(scale[u] / std::sqrt(4.0 * s.size()));
      } else {
        for (int i = 0; i < x.NumParameters(); ++i, ++j)
          sg.push_back(j < par_sigma.size() ? par_sigma[j] : std::nan(""));
      }
      for (auto& e : rep.effects)
        if (!terms[k].undecided && e.name == Name(x.effect) && e.where == x.Where(rig.names))
          for (size_t i = 0; i < sg.size(); ++i) {
            e.parameters[i].second = terms[k].parameters[i];
            e.sigma[i].second = sg[i];
          }
    }
  }
}

// Moves for the whole recording at all cameras but one (or at all) are not identifiable:
// the target's poses are free, so camera a moved by Ma and camera b by Mb give the same
// images as every other camera moved by Ma^-1 and b by Ma^-1 Mb (two cameras: a move of
// either). Time offsets likewise: the same offset at every camera is a shift of the
// target's (free) trajectory, so offsets (0, a, b) of three cameras give the same images as
// (-a, 0, b - a) or (-b, a - b, 0). The images cannot say which cameras moved (or lag); the
// terms stay in the model (the poses need them) but are reported as one undecided group of
// every camera seen.
void UndecideUnidentifiable(const Auditor& a, const CameraRig& rig, Effect effect, std::vector<CameraModelTerm>* terms,
                            AuditReport* rep) {
  const int nc = static_cast<int>(rig.size());
  int seen = 0;
  for (int c = 0; c < nc; ++c) seen += a.CameraSamples(c).empty() ? 0 : 1;
  std::vector<CameraModelTerm*> found;
  for (auto& t : *terms)
    if (!t.undecided && t.extension.effect == effect && !(t.from_time_s > -std::numeric_limits<double>::infinity()))
      found.push_back(&t);
  if (seen < 2 || found.empty() || static_cast<int>(found.size()) < seen - 1) return;
  std::vector<std::string> group;
  for (int c = 0; c < nc; ++c)
    if (!a.CameraSamples(c).empty()) group.push_back(Extension{effect, c, 0}.Label(rig.names));
  std::string named;
  for (CameraModelTerm* t : found) {
    t->undecided = true;
    const std::string where = t->extension.Where(rig.names);
    named += (named.empty() ? "" : ", ") + where;
    Unname(Name(effect), where, rep);
  }
  rep->undecided.push_back(group);
  const std::string what = effect == Effect::kCameraMoved ? "moves" : "time offsets";
  rep->notes.push_back(std::string(Name(effect)) + " fitted at " + named + " of " + std::to_string(seen) +
                       " cameras: " + what +
                       " at all cameras but one are not identifiable (the target's poses are free, so the same images "
                       "come from the other cameras' instead); which cameras is undecided");
}

// A named intrinsic effect or time offset is judged against what could stand in its place
// with as many parameters: the same effect at every other camera, and the camera's other
// effects of its size (focal length, k1 and time offset have one parameter each), by the
// joint fit (Auditor::JointFit: every term and every frame's pose fitted together). A fault
// of one camera pulls the poses all cameras share, so in a small rig the same effect
// elsewhere, with the other terms, may explain the images as well; and a focal length and a
// k1 differ only in how the image scales with the distance from its centre, which a target
// seen near the centre does not show. Where a stand-in explains the images as well (within
// undecided_nats of log-likelihood), the images do not say which it is: the group is
// reported undecided and the term kept in the model, unnamed.
void UndecideSwappableEffects(const Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
                              const std::vector<double>& scale, const std::vector<bool>& noise_named,
                              std::vector<CameraModelTerm>* terms_io, AuditReport* rep) {
  std::vector<CameraModelTerm>& terms = *terms_io;
  const int nc = static_cast<int>(rig.size());
  std::vector<CameraModelTerm> fitted = terms;
  const double base = a.JointFit(&fitted, scale);
  for (size_t k = 0; k < terms.size(); ++k) {
    const Extension x = terms[k].extension;
    if (terms[k].undecided ||
        (x.effect != Effect::kFocalLength && x.effect != Effect::kPrincipalPoint &&
         x.effect != Effect::kRadialDistortion && x.effect != Effect::kCameraTimeOffset))
      continue;
    std::vector<Extension> stand_ins;
    for (int c = 0; c < nc; ++c)
      if (c != x.index) stand_ins.push_back(Extension{x.effect, c, 0});
    for (Effect e : {Effect::kFocalLength, Effect::kPrincipalPoint, Effect::kRadialDistortion,
                     Effect::kCameraTimeOffset})
      if (e != x.effect && Extension{e, x.index, 0}.NumParameters() == x.NumParameters())
        stand_ins.push_back(Extension{e, x.index, 0});
    std::vector<std::string> group;
    for (const Extension& y : stand_ins) {
      if (a.CameraSamples(y.index).empty()) continue;
      if (y.effect == Effect::kRadialDistortion && !HasK1(rig.cameras[y.index])) continue;
      bool taken = false;
      for (const auto& t : terms) taken = taken || (t.extension.effect == y.effect && t.extension.index == y.index);
      if (taken) continue;
      std::vector<CameraModelTerm> t = terms;
      t[k].extension = y;
      t[k].parameters = y.InitialParameters();
      // A stand-in at the same camera is judged on the same samples as the term was
      // selected on: it must also predict the held-out folds as well (the selection's tie
      // rule), not only fit the joint likelihood as well.
      if (y.index == x.index) {
        const ScaleMode mode = UnitScaleMode(true, x.index, noise_named);
        const double named_ll = CameraHeldOut(a, options, true, x.index, terms, UnitTerms(terms, true, x.index), scale, mode).ll;
        const double stand_ll = CameraHeldOut(a, options, true, x.index, t, UnitTerms(t, true, x.index), scale, mode).ll;
        if (stand_ll < named_ll - options.undecided_nats) continue;
      }
      const double ll = a.JointFit(&t, scale);
      if (ll >= base - options.undecided_nats) group.push_back(t[k].extension.Label(rig.names));
    }
    if (group.empty()) continue;
    const std::string label = x.Label(rig.names), where = x.Where(rig.names);
    group.insert(group.begin(), label);
    terms[k].undecided = true;
    Unname(Name(x.effect), where, rep);
    rep->undecided.push_back(group);
    std::string others;
    for (size_t i = 1; i < group.size(); ++i) others += (i > 1 ? ", " : "") + group[i];
    char band[32];
    std::snprintf(band, sizeof band, "%.3g", options.undecided_nats);
    // Principal points of different cameras trade against each other through the target's
    // free poses: say so, so that the group is not read as a want of frames.
    bool elsewhere = false;
    for (size_t i = 1; i < group.size(); ++i)
      elsewhere = elsewhere || group[i].substr(group[i].rfind(" at ") + 4) != where;
    const std::string why =
        x.effect == Effect::kPrincipalPoint && elsewhere
            ? "; principal points of different cameras trade against each other through the target's free poses "
              "(moving the target along one camera's line of sight leaves that camera's image nearly unchanged and "
              "shifts the other cameras' images nearly uniformly), so a small one is not placed at its camera by "
              "these images"
            : "";
    rep->notes.push_back(label + " was selected, but " + others + " in its place, with every other term and the poses " +
                         "refitted, explains the images as well (joint log-likelihood within " + band +
                         " nats): which is undecided" + why);
  }
}

// The named terms' values and sigmas from the joint fit (every term and every frame's pose
// together: the maximum likelihood, its covariance with the poses marginalised), not from
// each unit's fit on leave-one-out poses, which a neighbour's fault still pulls and whose
// sigma leaves out the poses' own error. The noise scales stay the units' fits.
void JointEstimates(const Auditor& a, const CameraRig& rig, const std::vector<double>& scale,
                    std::vector<CameraModelTerm>* terms_io, AuditReport* rep) {
  std::vector<CameraModelTerm>& terms = *terms_io;
  if (terms.empty()) return;
  std::vector<CameraModelTerm> joint = terms;
  std::vector<std::vector<double>> sigma;
  a.JointFit(&joint, scale, &sigma);
  for (size_t k = 0; k < terms.size(); ++k) {
    const Extension& x = terms[k].extension;
    if (x.effect == Effect::kPixelNoiseScale) continue;
    terms[k].parameters = joint[k].parameters;
    if (terms[k].undecided) continue;
    for (auto& e : rep->effects)
      if (e.name == Name(x.effect) && e.where == x.Where(rig.names))
        for (size_t i = 0; i < sigma[k].size() && i < e.sigma.size(); ++i) {
          e.parameters[i].second = terms[k].parameters[i];
          e.sigma[i].second = sigma[k][i];
        }
  }
}


}  // namespace mcms::camera_audit
