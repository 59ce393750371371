#include "audit/lens_audit.h"

#include <numbers>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/output_folder.h"
#include "core/parallel.h"
#include "core/svg_plot.h"
#include "audit/model_selection.h"
#include "vision/camera_model.h"
#include "vision/mrcal_c.h"

namespace mcms {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kMinBoardInliers = 4;  // corners in use that fix a board's pose

// One camera's chessboard problem: observation i has its own board pose.
struct Problem {
  int width = 0, height = 0, bw = 0, bh = 0;
  double spacing = 0.0;
  std::vector<mrcal_point3_t> pool;  // Nobs * bh * bw: x, y, weight (< 0: outlier)
  std::vector<mrcal_pose_t> frames;  // seeds: T_cam_board as rt
  bool has_warp = false;
  mrcal_calobject_warp_t warp{};
  int boards_without_inliers = 0;    // observations left out: fewer than kMinBoardInliers in use
  int Nobs() const { return static_cast<int>(frames.size()); }
  int PointsPer() const { return bw * bh; }
};

mrcal_lensmodel_t Lensmodel(const std::string& name) {
  mrcal_lensmodel_t m;
  if (!mrcal_lensmodel_from_name(&m, name.c_str()) || !mrcal_lensmodel_type_is_valid(m.type))
    Throw("audit lens: lens model '", name, "' is not one mrcal knows (e.g. LENSMODEL_OPENCV8, "
          "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=30_Ny=20_fov_x_deg=170)");
  return m;
}
bool IsSplined(const std::string& name) { return name.rfind("LENSMODEL_SPLINED", 0) == 0; }

// The result of one solve on a subset of the observations.
struct Solve {
  std::vector<double> intrinsics;
  std::vector<mrcal_pose_t> frames;  // of the subset, in its order
  mrcal_calobject_warp_t warp{};
  std::vector<double> x;             // board residuals of the subset (weighted; 0 for outliers)
  double rss = 0.0;
  long n = 0;                        // residual coordinates with weight > 0
  bool ok = false;
};

enum class Free { kLens, kLensNoCore, kPosesOnly };

Solve RunMrcal(const Problem& p, const std::string& lensmodel, const std::vector<double>& intrinsics,
               const std::vector<int>& subset, const std::vector<mrcal_pose_t>& frame_seeds,
               const mrcal_calobject_warp_t& warp, Free free) {
  const mrcal_lensmodel_t lm = Lensmodel(lensmodel);
  Solve s;
  s.intrinsics = intrinsics;
  s.frames = frame_seeds;
  s.warp = warp;
  const int nobs = static_cast<int>(subset.size());
  const int per = p.PointsPer();
  std::vector<mrcal_observation_board_t> obs(static_cast<size_t>(nobs));
  std::vector<mrcal_point3_t> pool(static_cast<size_t>(nobs) * static_cast<size_t>(per));
  for (int i = 0; i < nobs; ++i) {
    obs[static_cast<size_t>(i)].icam.intrinsics = 0;
    obs[static_cast<size_t>(i)].icam.extrinsics = -1;
    obs[static_cast<size_t>(i)].iframe = i;
    std::copy_n(p.pool.begin() + static_cast<long>(subset[static_cast<size_t>(i)]) * per, per,
                pool.begin() + static_cast<long>(i) * per);
  }
  mrcal_problem_selections_t sel{};
  sel.do_optimize_intrinsics_core = free == Free::kLens;
  sel.do_optimize_intrinsics_distortions = free != Free::kPosesOnly;
  sel.do_optimize_extrinsics = false;
  sel.do_optimize_frames = true;
  sel.do_optimize_calobject_warp = p.has_warp && free != Free::kPosesOnly;
  sel.do_apply_regularization = free != Free::kPosesOnly;
  sel.do_apply_outlier_rejection = false;
  const mrcal_problem_constants_t constants{0.0, 1e9};
  const int imagersize[2] = {p.width, p.height};
  const int nx = mrcal_num_measurements(nobs, 0, p.bw, p.bh, 1, 0, nobs, 0, 0, sel, &lm);
  std::vector<double> x(static_cast<size_t>(nx));
  const mrcal_stats_t stats =
      mrcal_optimize(nullptr, 0, x.data(), nx * static_cast<int>(sizeof(double)), s.intrinsics.data(), nullptr, s.frames.data(), nullptr,
                     p.has_warp ? &s.warp : nullptr, 1, 0, nobs, 0, 0, obs.data(), nullptr, nobs, 0, pool.data(), &lm,
                     imagersize, sel, &constants, p.spacing, p.bw, p.bh, false, false);
  s.ok = std::isfinite(stats.rms_reproj_error__pixels) && stats.rms_reproj_error__pixels >= 0;
  const int nb = mrcal_num_measurements_boards(nobs, p.bw, p.bh);
  s.x.assign(x.begin(), x.begin() + nb);
  for (int k = 0; k < nobs * per; ++k) {
    if (pool[static_cast<size_t>(k)].z <= 0) continue;
    const double ex = x[2 * static_cast<size_t>(k)], ey = x[2 * static_cast<size_t>(k) + 1];
    s.rss += ex * ex + ey * ey;
    s.n += 2;
  }
  return s;
}

// The nominal model's horizontal field of view (deg): the rays of the image's left and
// right edge centres; 0 when they do not unproject.
double HorizontalFovDeg(const std::string& lensmodel, const std::vector<double>& intrinsics, int w, int h) {
  const mrcal_lensmodel_t lm = Lensmodel(lensmodel);
  mrcal_point2_t q[2];
  q[0].x = 0.0, q[0].y = (h - 1) / 2.0;
  q[1].x = w - 1.0, q[1].y = (h - 1) / 2.0;
  mrcal_point3_t v[2];
  if (!mrcal_unproject(v, q, 2, &lm, intrinsics.data())) return 0.0;
  double fov = 0.0;
  for (const auto& r : v) {
    const double a = std::atan2(std::hypot(r.x, r.y), r.z);
    if (!std::isfinite(a)) return 0.0;
    fov += a * 180.0 / kPi;
  }
  return fov;
}

Problem MakeProblem(const MrcalOptimizationInputsData& d) {
  Problem p;
  const int icam = d.icam_intrinsics;
  p.width = d.imagersizes.at(static_cast<size_t>(icam))[0];
  p.height = d.imagersizes.at(static_cast<size_t>(icam))[1];
  p.bw = d.board_width_n;
  p.bh = d.board_height_n;
  p.spacing = d.spacing_m;
  p.has_warp = d.has_calobject_warp;
  p.warp.x2 = d.calobject_warp[0];
  p.warp.y2 = d.calobject_warp[1];
  const size_t per = static_cast<size_t>(p.bw * p.bh);
  for (size_t i = 0; i < d.indices_frame_camintrinsics_camextrinsics.size(); ++i) {
    const auto& idx = d.indices_frame_camintrinsics_camextrinsics[i];
    if (idx[1] != icam) continue;
    const auto& f = d.frames_rt_toref.at(static_cast<size_t>(idx[0]));
    double rt[6] = {f[0], f[1], f[2], f[3], f[4], f[5]};
    if (idx[2] >= 0) {  // T_cam_board = T_cam_ref T_ref_board
      const auto& e = d.extrinsics_rt_fromref.at(static_cast<size_t>(idx[2]));
      const double e6[6] = {e[0], e[1], e[2], e[3], e[4], e[5]};
      double out[6];
      mrcal_compose_rt(out, nullptr, nullptr, nullptr, nullptr, e6, rt);
      std::copy_n(out, 6, rt);
    }
    mrcal_pose_t pose;
    pose.r.x = rt[0], pose.r.y = rt[1], pose.r.z = rt[2];
    pose.t.x = rt[3], pose.t.y = rt[4], pose.t.z = rt[5];
    std::vector<mrcal_point3_t> board(per);
    int inliers = 0;
    for (size_t k = 0; k < per; ++k) {
      mrcal_point3_t& q = board[k];
      q.x = d.observations_board[3 * (i * per + k)];
      q.y = d.observations_board[3 * (i * per + k) + 1];
      q.z = d.observations_board[3 * (i * per + k) + 2];
      inliers += q.z > 0;
    }
    // A board with fewer than 4 corners in use (the file's outliers have weight <= 0) fixes
    // no pose: it would leave the solver a singular system. Left out, and counted.
    if (inliers < kMinBoardInliers) {
      ++p.boards_without_inliers;
      continue;
    }
    p.frames.push_back(pose);
    p.pool.insert(p.pool.end(), board.begin(), board.end());
  }
  return p;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string Fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

}  // namespace

bool LensAuditOptions::IsValid(std::string* why) const {
  const auto fail = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (!(false_alarm > 0 && false_alarm < 1)) return fail("--false-alarm must be in (0, 1), got " + Fmt("%g", false_alarm));
  if (folds < 2) return fail("--folds must be >= 2, got " + std::to_string(folds));
  if (threads < 0 || threads > kMaxThreads)
    return fail("--threads must be in 0.." + std::to_string(kMaxThreads) + " (0: all cores), got " + std::to_string(threads));
  if (spline_nx < 4) return fail("the spline needs >= 4 knots across, got " + std::to_string(spline_nx));
  if (spline_ny != 0 && spline_ny < 4) return fail("the spline needs >= 4 knots down, got " + std::to_string(spline_ny));
  return true;
}

namespace {

// The decision into the report: the named lens model, or the undecided ones.
void ReportLensDecision(const StepDecision& d, const std::vector<SelectionCandidate>& cands, const std::string& nominal,
                        LensAuditResult* r_out) {
  LensAuditResult& r = *r_out;
  AuditReport& rep = r.report;
  const LensFit& nom = r.fits[0];
  const auto effect_of = [&](int ci) {
    const LensFit& f = r.fits[static_cast<size_t>(ci) + 1];
    AuditEffect e;
    e.name = "lens_model";
    e.where = r.camera;
    e.labels = {{"lensmodel", f.lensmodel}, {"nominal_lensmodel", nominal}};
    e.parameters = {{"parameters_added", static_cast<double>(cands[static_cast<size_t>(ci)].k)},
                    {"rms_px_before", nom.rms_px},
                    {"rms_px_after", f.rms_px},
                    {"heldout_loglik_before", nom.heldout_loglik},
                    {"heldout_loglik_after", f.heldout_loglik}};
    e.heldout_rms_before = nom.heldout_rms_px;
    e.heldout_rms_after = f.heldout_rms_px;
    e.heldout_loglik_gain = cands[static_cast<size_t>(ci)].heldout_gain;
    e.bic_gain = cands[static_cast<size_t>(ci)].bic_gain;
    return e;
  };
  if (d.outcome == StepOutcome::kNamed) {
    rep.effects.push_back(effect_of(d.best));
    r.chosen = d.best + 1;
  } else if (d.outcome == StepOutcome::kUndecided) {
    std::vector<std::string> g;
    for (int i : d.group) g.push_back("lens_model " + r.fits[static_cast<size_t>(i) + 1].lensmodel + " at " + r.camera);
    rep.undecided.push_back(g);
  }
}

}  // namespace

LensAuditResult AuditLens(const MrcalOptimizationInputsData& data, const LensAuditOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) Throw("audit lens: ", why);
  const auto log = [&](const std::string& s) {
    if (options.progress) options.progress(s);
  };
  const Problem p = MakeProblem(data);
  LensAuditResult r;
  r.camera = "cam" + std::to_string(data.icam_intrinsics);
  r.width = p.width;
  r.height = p.height;
  for (const mrcal_point3_t& q : p.pool) r.observed.push_back({q.x, q.y, q.z});
  r.points_per_board = std::max(1, p.PointsPer());
  if (p.boards_without_inliers > 0)
    r.report.notes.push_back(std::to_string(p.boards_without_inliers) + " board observation(s) of " + r.camera +
                             " have fewer than " + std::to_string(kMinBoardInliers) +
                             " corners in use (the file marks the others outliers): left out");
  if (p.Nobs() < options.folds)
    Throw("audit lens: camera ", r.camera, " has ", p.Nobs(), " board observations",
          p.boards_without_inliers > 0 ? std::string(" with ").append(std::to_string(kMinBoardInliers)).append(
                                             " or more corners in use (").append(std::to_string(p.boards_without_inliers)).append(
                                             " more have their corners marked outliers in the file)")
                                       : std::string(),
          ", fewer than the ", options.folds, " folds");
  const std::string nominal = data.lensmodel;
  const std::vector<double>& nominal_intrinsics = data.intrinsics.at(static_cast<size_t>(data.icam_intrinsics));
  const int nominal_params = mrcal_lensmodel_num_params(&static_cast<const mrcal_lensmodel_t&>(Lensmodel(nominal)));
  if (static_cast<int>(nominal_intrinsics.size()) != nominal_params)
    Throw("audit lens: the file's intrinsics have ", nominal_intrinsics.size(), " values, ", nominal, " has ",
          nominal_params);
  if (IsSplined(nominal)) Throw("audit lens: the nominal model ", nominal, " is already splined; nothing richer to try");

  // Candidates.
  const auto default_splined = [&] {
    double fov = HorizontalFovDeg(nominal, nominal_intrinsics, p.width, p.height);
    if (!(fov > 1.0)) fov = 120.0;
    const int fov_deg = std::min(179, static_cast<int>(std::ceil(fov * 1.05)));
    const int ny = options.spline_ny > 0 ? options.spline_ny
                                         : std::max(4, static_cast<int>(std::lround(options.spline_nx * double(p.height) / p.width)));
    return "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=" + std::to_string(options.spline_nx) +
           "_Ny=" + std::to_string(ny) + "_fov_x_deg=" + std::to_string(fov_deg);
  };
  std::vector<std::string> candidates;
  if (options.candidates.empty()) {
    for (const char* c : {"LENSMODEL_OPENCV8", "LENSMODEL_OPENCV12"}) candidates.push_back(c);
    candidates.push_back("splined");
  } else {
    candidates = options.candidates;
  }
  std::vector<std::string> names;
  for (std::string c : candidates) {
    if (c == "splined") c = default_splined();
    const mrcal_lensmodel_t lm = Lensmodel(c);
    const int k = mrcal_lensmodel_num_params(&lm);
    const bool richer = IsSplined(c) ? true : k > nominal_params;
    if (!richer) {
      r.report.notes.push_back(c + " is not richer than the nominal " + nominal + ": not a candidate");
      continue;
    }
    if (!IsSplined(c) && !IsSplined(nominal) && c.rfind("LENSMODEL_OPENCV", 0) != 0)
      Throw("audit lens: candidate ", c, " is neither an OpenCV model richer than the nominal nor a splined model");
    if (std::find(names.begin(), names.end(), c) == names.end()) names.push_back(c);
  }

  std::vector<int> all(static_cast<size_t>(p.Nobs()));
  std::iota(all.begin(), all.end(), 0);
  const auto frames_of = [&](const std::vector<mrcal_pose_t>& fr, const std::vector<int>& subset) {
    std::vector<mrcal_pose_t> out;
    for (int i : subset) out.push_back(fr[static_cast<size_t>(i)]);
    return out;
  };

  // Seeds for a candidate: the nominal's intrinsics padded with zeros (OpenCV models
  // extend each other), or the nominal's core with a flat spline.
  const auto seed = [&](const std::string& c) {
    const mrcal_lensmodel_t lm = Lensmodel(c);
    std::vector<double> s(static_cast<size_t>(mrcal_lensmodel_num_params(&lm)), 0.0);
    if (IsSplined(c)) std::copy_n(nominal_intrinsics.begin(), 4, s.begin());
    else std::copy(nominal_intrinsics.begin(), nominal_intrinsics.end(), s.begin());
    return s;
  };
  const auto free_of = [](const std::string& c) { return IsSplined(c) ? Free::kLensNoCore : Free::kLens; };
  const auto free_count = [&](const std::string& c) {
    const mrcal_lensmodel_t lm = Lensmodel(c);
    return mrcal_lensmodel_num_params(&lm) - (IsSplined(c) ? 4 : 0);
  };

  // Fits on all data and on the folds.
  const auto fit = [&](const std::string& c, const std::vector<double>& seed_intrinsics) {
    const auto t0 = std::chrono::steady_clock::now();
    LensFit f;
    f.lensmodel = c;
    f.free_intrinsics = free_count(c);
    log("fitting " + c + " to " + std::to_string(p.Nobs()) + " board observations");
    Solve s = RunMrcal(p, c, seed_intrinsics, all, p.frames, p.warp, free_of(c));
    f.converged = s.ok;
    f.intrinsics = s.intrinsics;
    f.rss = s.rss;
    f.residuals = s.x;
    f.n = s.n;
    f.rms_px = s.n > 0 ? std::sqrt(s.rss / static_cast<double>(s.n)) : 0.0;
    log(c + ": RMS " + Fmt("%.4f", f.rms_px) + " px (" + Fmt("%.1f", Seconds(t0)) + " s); " +
        std::to_string(options.folds) + " held-out folds:");
    // The folds are independent solves (mrcal_optimize keeps its state in its own
    // context): run side by side, summed in fold order so that the result does not
    // depend on the threads.
    struct FoldScore {
      double rss = 0.0, loglik = 0.0;
      long n = 0;
    };
    std::vector<FoldScore> scores(static_cast<size_t>(options.folds));
    size_t reported = 0;
    ParallelFor(
        scores.size(), ThreadsToUse(options.threads),
        [&](size_t fold) {
          std::vector<int> train, test;
          for (int i = 0; i < p.Nobs(); ++i)
            ((options.contiguous_folds ? TimeBlockFold(i, p.Nobs(), options.folds) : i % options.folds) == static_cast<int>(fold) ? test : train).push_back(i);
          const Solve tr = RunMrcal(p, c, s.intrinsics, train, frames_of(s.frames, train), s.warp, free_of(c));
          const double dof = static_cast<double>(tr.n) - f.free_intrinsics - 6.0 * static_cast<double>(train.size()) -
                             (p.has_warp ? 2.0 : 0.0);
          if (!(dof > 0)) Throw("audit lens: ", c, " has more parameters than the training folds have residuals");
          const double var = tr.rss / dof;
          const Solve te = RunMrcal(p, c, tr.intrinsics, test, frames_of(s.frames, test), tr.warp, Free::kPosesOnly);
          scores[fold] = {te.rss, -0.5 * te.rss / var - 0.5 * static_cast<double>(te.n) * std::log(2.0 * kPi * var), te.n};
        },
        [&](size_t done, size_t n) {
          if (done == reported || done == n) return;
          reported = done;
          log("  " + std::to_string(done) + " of " + std::to_string(n) + " folds solved (" + Fmt("%.1f", Seconds(t0)) + " s)");
        });
    double sum_sq = 0.0;
    long count = 0;
    for (size_t fold = 0; fold < scores.size(); ++fold) {
      sum_sq += scores[fold].rss;
      count += scores[fold].n;
      f.heldout_loglik += scores[fold].loglik;
      log("  fold " + std::to_string(fold + 1) + "/" + std::to_string(options.folds) + ": held-out RMS " +
          Fmt("%.4f", scores[fold].n ? std::sqrt(scores[fold].rss / static_cast<double>(scores[fold].n)) : 0.0) + " px");
    }
    f.heldout_rms_px = count > 0 ? std::sqrt(sum_sq / static_cast<double>(count)) : 0.0;
    f.seconds = Seconds(t0);
    return f;
  };

  r.fits.push_back(fit(nominal, nominal_intrinsics));
  const LensFit nom = r.fits[0];  // a copy: r.fits grows below
  if (!nom.converged || nom.n == 0) Throw("audit lens: the nominal model ", nominal, " could not be fitted");
  // A candidate needs a training fold with more residuals than parameters (lens, poses);
  // one that cannot have it is left out with a note instead of failing the audit.
  const double train_share = (options.folds - 1.0) / options.folds;
  for (const std::string& c : names) {
    const double params = free_count(c) + 6.0 * p.Nobs() * train_share + (p.has_warp ? 2.0 : 0.0);
    if (!(static_cast<double>(nom.n) * train_share > 2.0 * params)) {
      r.report.notes.push_back(c + ": not tried: " + std::to_string(nom.n) + " residuals are too few for its " +
                               std::to_string(free_count(c)) + " lens parameters (the training folds need twice " +
                               "as many residuals as parameters)");
      continue;
    }
    r.fits.push_back(fit(c, seed(c)));
  }

  // Selection.
  SelectionRule rule;
  rule.alpha = options.false_alarm;
  rule.ln_n = std::log(static_cast<double>(nom.n));
  std::vector<SelectionCandidate> cands;
  for (size_t i = 1; i < r.fits.size(); ++i) {
    SelectionCandidate sc;
    sc.k = r.fits[i].free_intrinsics - nom.free_intrinsics;
    const bool ok = r.fits[i].converged && r.fits[i].rss > 0;
    sc.lr = ok ? static_cast<double>(nom.n) * std::log(nom.rss / r.fits[i].rss) : 0.0;
    sc.heldout_gain = r.fits[i].heldout_loglik - nom.heldout_loglik;
    cands.push_back(sc);
  }
  const StepDecision d = cands.empty() ? StepDecision{} : DecideStep(cands, static_cast<int>(cands.size()), rule);
  // A richer lens model never fits worse than the one it contains (issue 51).
  const double nominal_ll =
      -0.5 * static_cast<double>(nom.n) * (std::log(2 * std::numbers::pi * nom.rss / std::max(1L, nom.n)) + 1);
  for (size_t i = 1; i < r.fits.size(); ++i)
    if (r.fits[i].converged && r.fits[i].rss > 0) r.report.nested.Record(cands[i - 1].lr, nominal_ll);

  AuditReport& rep = r.report;
  rep.mode = "lens";
  rep.rms_unit = "px";
  rep.nominal_n = nom.n;
  // chi2/dof against the richest candidate's noise estimate.
  double best_var = nom.rss / static_cast<double>(nom.n);
  for (size_t i = 1; i < r.fits.size(); ++i)
    if (r.fits[i].converged && r.fits[i].n > 0)
      best_var = std::min(best_var, r.fits[i].rss / std::max(1.0, static_cast<double>(r.fits[i].n - r.fits[i].free_intrinsics)));
  rep.nominal_chi2_per_dof = (nom.rss / static_cast<double>(nom.n)) / best_var;
  for (size_t i = 1; i < r.fits.size(); ++i) {
    const SelectionCandidate& sc = cands[i - 1];
    AuditTest t;
    t.name = "likelihood ratio " + r.fits[i].lensmodel + " vs " + nominal + " (k = " + std::to_string(sc.k) + ")";
    t.statistic = sc.lr;
    t.p_value = sc.p_value;
    t.failed = sc.passes;
    rep.tests.push_back(t);
  }
  ReportLensDecision(d, cands, nominal, &r);
  rep.clean = rep.effects.empty() && rep.undecided.empty();
  for (const LensFit& f : r.fits)
    rep.notes.push_back(f.lensmodel + ": " + std::to_string(f.free_intrinsics) + " free lens parameters, RMS " +
                        Fmt("%.4f", f.rms_px) + " px over " + std::to_string(f.n) + " residuals, held-out RMS " +
                        Fmt("%.4f", f.heldout_rms_px) + " px, held-out log-likelihood " + Fmt("%.1f", f.heldout_loglik) +
                        (f.converged ? "" : " (the solve failed)") + ", " + Fmt("%.1f", f.seconds) + " s");
  rep.notes.push_back("camera " + r.camera + ", " + std::to_string(p.Nobs()) + " board observations, " +
                      std::to_string(options.folds) + (options.contiguous_folds ? " folds of contiguous observations" : " interleaved folds (board i in fold i mod folds)") + "; the file's outliers are "
                      "left out of every fit, none are added; nominal chi2/dof = its residual variance over the "
                      "richest candidate's");
  if (d.outcome == StepOutcome::kNoHeldoutGain)
    rep.notes.push_back("a richer lens fits all data better but gains nothing on held-out boards");
  return r;
}

int LensAuditResult::Compared() const {
  if (chosen > 0) return chosen;
  int best = -1;
  for (size_t i = 1; i < fits.size(); ++i)
    if (fits[i].converged && (best < 0 || fits[i].heldout_loglik > fits[static_cast<size_t>(best)].heldout_loglik))
      best = static_cast<int>(i);
  return best;
}

namespace {

// Mean residual vectors in a grid of cells over the image, and the radial component's
// mean in rings of distance from the image centre.
struct Binned {
  std::vector<double> u, v, du, dv;  // cells with points
  std::vector<double> radius, radial, radial_low, radial_high;
};

Binned Bin(const LensAuditResult& r, const std::vector<double>& x, int nx) {
  const int ny = std::max(1, static_cast<int>(std::lround(nx * double(r.height) / r.width)));
  std::vector<double> su(static_cast<size_t>(nx * ny)), sv(su.size()), cnt(su.size());
  constexpr int kRings = 24;
  const double cu = (r.width - 1) / 2.0, cv = (r.height - 1) / 2.0, rmax = std::hypot(cu, cv);
  std::vector<double> rs(kRings), rss(kRings), rn(kRings);
  for (size_t k = 0; k < r.observed.size() && 2 * k + 1 < x.size(); ++k) {
    const auto& o = r.observed[k];
    if (!(o[2] > 0)) continue;
    const double ex = x[2 * k], ey = x[2 * k + 1];
    const int i = std::clamp(static_cast<int>(o[0] / r.width * nx), 0, nx - 1);
    const int j = std::clamp(static_cast<int>(o[1] / r.height * ny), 0, ny - 1);
    const size_t c = static_cast<size_t>(j * nx + i);
    su[c] += ex, sv[c] += ey, cnt[c] += 1;
    const double du = o[0] - cu, dv = o[1] - cv, rad = std::hypot(du, dv);
    if (rad < 1e-9) continue;
    const double radial = (ex * du + ey * dv) / rad;
    const size_t ring = static_cast<size_t>(std::clamp(static_cast<int>(rad / rmax * kRings), 0, kRings - 1));
    rs[ring] += radial, rss[ring] += radial * radial, rn[ring] += 1;
  }
  Binned b;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const size_t c = static_cast<size_t>(j * nx + i);
      if (cnt[c] < 3) continue;
      b.u.push_back((i + 0.5) * r.width / nx);
      b.v.push_back((j + 0.5) * r.height / ny);
      b.du.push_back(su[c] / cnt[c]);
      b.dv.push_back(sv[c] / cnt[c]);
    }
  for (int k = 0; k < kRings; ++k) {
    if (rn[static_cast<size_t>(k)] < 10) continue;
    const double n = rn[static_cast<size_t>(k)], m = rs[static_cast<size_t>(k)] / n;
    const double sd = std::sqrt(std::max(0.0, rss[static_cast<size_t>(k)] / n - m * m));
    b.radius.push_back((k + 0.5) * rmax / kRings);
    b.radial.push_back(m);
    b.radial_low.push_back(m - 2 * sd / std::sqrt(n));  // +-2 standard errors of the mean
    b.radial_high.push_back(m + 2 * sd / std::sqrt(n));
  }
  return b;
}

std::string Short(const std::string& lensmodel) {
  const size_t cut = lensmodel.find("_order=");
  return (lensmodel.rfind("LENSMODEL_", 0) == 0 ? lensmodel.substr(10, cut == std::string::npos ? std::string::npos : cut - 10)
                                                 : lensmodel);
}

}  // namespace

void WriteLensAuditFiles(const LensAuditResult& r, const std::filesystem::path& dir) {
  const int cmp = r.Compared();
  const LensFit& nom = r.fits.at(0);
  WriteFolderAtomically(dir, {"report.json"}, "audit lens", "audit lens -o", [&](const std::filesystem::path& d) {
    WriteFileAtomically(d / "report.txt", [&](std::ostream& os) { os << r.report.Text(); });
    r.report.WriteJson(d / "report.json");
    WriteFileAtomically(d / "residuals.csv", [&](std::ostream& os) {
      os << "board,point,u_px,v_px,weight,nominal_ex_px,nominal_ey_px"
         << (cmp > 0 ? ",candidate_ex_px,candidate_ey_px" : "") << "\n";
      const size_t per = static_cast<size_t>(r.points_per_board);
      char b[256];
      for (size_t k = 0; k < r.observed.size() && 2 * k + 1 < nom.residuals.size(); ++k) {
        const auto& o = r.observed[k];
        std::snprintf(b, sizeof b, "%zu,%zu,%.4f,%.4f,%.4g,%.5f,%.5f", k / per, k % per, o[0], o[1], o[2],
                      nom.residuals[2 * k], nom.residuals[2 * k + 1]);
        os << b;
        if (cmp > 0) {
          const auto& c = r.fits[static_cast<size_t>(cmp)].residuals;
          std::snprintf(b, sizeof b, ",%.5f,%.5f", c[2 * k], c[2 * k + 1]);
          os << b;
        }
        os << "\n";
      }
    });
    std::filesystem::create_directories(d / "plots");
    std::vector<const LensFit*> shown = {&nom};
    if (cmp > 0) shown.push_back(&r.fits[static_cast<size_t>(cmp)]);
    const char* colors[2] = {"#d62728", "#1f77b4"};
    std::vector<Plot> plots;
    std::vector<Binned> bins;
    double largest = 0.0;
    for (const LensFit* f : shown) {
      bins.push_back(Bin(r, f->residuals, 30));
      for (size_t i = 0; i < bins.back().du.size(); ++i)
        largest = std::max(largest, std::hypot(bins.back().du[i], bins.back().dv[i]));
    }
    // The largest mean vector drawn as 6 % of the image width, the same scale for both.
    double scale = 1.0;
    if (largest > 0) {  // a round magnification
      const double want = 0.06 * r.width / largest, decade = std::pow(10.0, std::floor(std::log10(want)));
      scale = want >= 5 * decade ? 5 * decade : want >= 2 * decade ? 2 * decade : decade;
    }
    for (size_t m = 0; m < shown.size(); ++m) {
      Plot img;
      char title[200];
      std::snprintf(title, sizeof title, "%s %s: mean residual per cell, arrows x%g", r.camera.c_str(),
                    Short(shown[m]->lensmodel).c_str(), scale);
      img.title = title;
      img.x_label = "u (px)";
      img.y_label = "v (px)";
      img.y_down = img.equal_scale = true;
      img.x_range = std::make_pair(0.0, double(r.width));
      img.y_range = std::make_pair(0.0, double(r.height));
      PlotSeries vec{Short(shown[m]->lensmodel), bins[m].u, bins[m].v, colors[m], false};
      vec.dx = bins[m].du;
      vec.dy = bins[m].dv;
      vec.vector_scale = scale;
      img.series = {vec};
      plots.push_back(img);
    }
    Plot radial;
    radial.title = r.camera + ": radial residual against the distance from the image centre (mean, +-2 s.e.)";
    radial.x_label = "distance from the image centre (px)";
    radial.y_label = "radial residual (px)";
    for (size_t m = 0; m < shown.size(); ++m) {
      PlotSeries s{Short(shown[m]->lensmodel), bins[m].radius, bins[m].radial, colors[m], false};
      s.y_low = bins[m].radial_low;
      s.y_high = bins[m].radial_high;
      radial.series.push_back(s);
    }
    plots.push_back(radial);
    WritePlotGridSvg(d / "plots" / (r.camera + ".svg"), plots, 2, 560, 400);
    if (r.chosen > 0) {
      const LensFit& f = r.fits[static_cast<size_t>(r.chosen)];
      CameraModel(f.lensmodel, f.intrinsics, r.width, r.height).WriteCameramodel(d / (r.camera + ".cameramodel"));
    }
  });
}

}  // namespace mcms
