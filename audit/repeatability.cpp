#include "audit/repeatability.h"

#include <numbers>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "core/error.h"
#include "core/nelder_mead.h"
#include "core/limits.h"
#include "core/io.h"
#include "core/statistics.h"
#include "core/svg_plot.h"

namespace mcms {

namespace fs = std::filesystem;

namespace {

// Natural order of point labels: numeric when both are numbers.
bool LabelLess(const std::string& a, const std::string& b) {
  char* ea = nullptr;
  char* eb = nullptr;
  const double x = std::strtod(a.c_str(), &ea), y = std::strtod(b.c_str(), &eb);
  const bool na = !a.empty() && *ea == 0, nb = !b.empty() && *eb == 0;
  if (na && nb && x != y) return x < y;
  return a < b;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// The noise-model fit

const std::vector<std::string>& CandidateEffects() {
  static const std::vector<std::string> c{"pixel_noise_scale", "noise_floor", "anisotropy_x", "anisotropy_y", "anisotropy_z",
                                          "misidentification"};
  return c;
}

double SampleVarianceLogLik(const Vec3& v, const Vec3& s2, int repeats) {
  const double nu = repeats - 1;
  double L = 0;
  for (int a = 0; a < 3; ++a) {
    const double x = nu * v[a] / s2[a];  // ~ chi-square(nu)
    L += std::log(nu / s2[a]) + (0.5 * nu - 1) * std::log(x) - 0.5 * x - 0.5 * nu * std::log(2.0) - std::lgamma(0.5 * nu);
  }
  return L;
}

Vec3 NoiseModelFit::InlierVariance(const Vec3& nominal) const {
  return scale * scale * nominal + Vec3::Constant(floor * floor) + anisotropy.cwiseAbs2();
}

double NoiseModelFit::PointLogLik(const Vec3& nominal, const Vec3& measured, int repeats) const {
  const Vec3 s2 = InlierVariance(nominal);
  const double Lin = SampleVarianceLogLik(measured, s2, repeats);
  if (!(outlier_probability > 0)) return Lin;
  const double Lout = SampleVarianceLogLik(measured, s2 + Vec3::Constant(outlier_sigma * outlier_sigma), repeats);
  const double a = std::log1p(-outlier_probability) + Lin, b = std::log(outlier_probability) + Lout;
  const double m = std::max(a, b);
  return m + std::log(std::exp(a - m) + std::exp(b - m));
}

namespace {

int NumParams(const std::vector<std::string>& effects) {
  int k = 0;
  for (const auto& e : effects) k += e == "misidentification" ? 2 : 1;
  return k;
}

// theta (unconstrained) -> the fit's fields.
void Apply(const std::vector<std::string>& effects, const std::vector<double>& th, NoiseModelFit* f) {
  f->scale = 1, f->floor = 0, f->outlier_probability = 0, f->outlier_sigma = 0;
  f->anisotropy.setZero();
  size_t k = 0;
  for (const auto& e : effects) {
    if (e == "pixel_noise_scale") f->scale = std::exp(th[k++]);
    else if (e == "noise_floor") f->floor = std::exp(th[k++]);
    else if (e == "anisotropy_x") f->anisotropy.x() = std::exp(th[k++]);
    else if (e == "anisotropy_y") f->anisotropy.y() = std::exp(th[k++]);
    else if (e == "anisotropy_z") f->anisotropy.z() = std::exp(th[k++]);
    else if (e == "misidentification") {
      f->outlier_probability = 1.0 / (1.0 + std::exp(-th[k++]));
      f->outlier_sigma = std::exp(th[k++]);
    } else {
      Throw<InternalError>("unknown noise effect '", e, "'");
    }
  }
}

double TotalLogLik(const VarianceData& d, const NoiseModelFit& f, size_t skip = static_cast<size_t>(-1)) {
  double L = 0;
  for (size_t i = 0; i < d.size(); ++i)
    if (i != skip) L += f.PointLogLik(d.nominal[i], d.measured[i], d.repeats[i]);
  return L;
}

// Starting values from the data.
std::vector<double> InitialTheta(const VarianceData& d, const std::vector<std::string>& effects) {
  std::vector<double> ratio, vmin, va[3], vmax;
  for (size_t i = 0; i < d.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      ratio.push_back(d.measured[i][a] / d.nominal[i][a]);
      va[a].push_back(d.measured[i][a]);
    }
    vmin.push_back(d.measured[i].minCoeff());
    vmax.push_back(d.measured[i].maxCoeff());
  }
  std::vector<double> th;
  for (const auto& e : effects) {
    if (e == "pixel_noise_scale") th.push_back(0.5 * std::log(SelectedMedian(ratio)));
    else if (e == "noise_floor") th.push_back(0.5 * std::log(SelectedMedian(vmin)));
    else if (e == "anisotropy_x") th.push_back(0.5 * std::log(SelectedMedian(va[0])));
    else if (e == "anisotropy_y") th.push_back(0.5 * std::log(SelectedMedian(va[1])));
    else if (e == "anisotropy_z") th.push_back(0.5 * std::log(SelectedMedian(va[2])));
    else if (e == "misidentification") {
      th.push_back(std::log(0.1 / 0.9));
      th.push_back(0.5 * std::log(*std::max_element(vmax.begin(), vmax.end())));
    }
  }
  return th;
}

struct ThetaFit {
  std::vector<double> theta;
  double loglik = -INFINITY;
};

ThetaFit FitTheta(const VarianceData& d, const std::vector<std::string>& effects, const std::vector<std::vector<double>>& starts,
                  size_t skip = static_cast<size_t>(-1)) {
  NoiseModelFit f;
  auto objective = [&](const std::vector<double>& th) {
    for (double t : th)
      if (!(std::abs(t) < 60)) return 1e300;
    Apply(effects, th, &f);
    const double L = TotalLogLik(d, f, skip);
    return std::isfinite(L) ? -L : 1e300;
  };
  ThetaFit best;
  for (const auto& s0 : starts) {
    std::vector<double> x = s0;
    double fx = 0;
    // Restarts from the optimum shake Nelder-Mead out of a collapsed simplex.
    for (int r = 0; r < 3; ++r) x = NelderMead(objective, x, r == 0 ? 1.0 : 0.3, 3000, &fx);
    if (-fx > best.loglik) best.loglik = -fx, best.theta = x;
  }
  return best;
}

// ln C(n, k)
double LogChoose(int n, int k) { return std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0); }

NoiseModelFit Finish(const VarianceData& d, const std::vector<std::string>& effects, const ThetaFit& t,
                     int num_candidates = static_cast<int>(CandidateEffects().size())) {
  NoiseModelFit f;
  f.effects = effects;
  Apply(effects, t.theta, &f);
  f.loglik = TotalLogLik(d, f);
  f.num_parameters = NumParams(effects);
  f.num_variances = 3 * d.size();
  // Extended BIC (Chen & Chen 2008, gamma = 1): the plain BIC plus 2 ln C(K, k) for k of K
  // candidate effects, so that searching K candidates does not raise the false alarms.
  f.bic = -2 * f.loglik + f.num_parameters * std::log(static_cast<double>(f.num_variances)) +
          2 * LogChoose(std::max<int>(num_candidates, static_cast<int>(effects.size())), static_cast<int>(effects.size()));
  // Standard errors: the observed information in theta by central differences, then the
  // delta method to the natural parameters.
  const size_t n = t.theta.size();
  std::vector<double> se(n, std::numeric_limits<double>::quiet_NaN());
  if (n > 0) {
    auto nll = [&](const std::vector<double>& th) {
      NoiseModelFit g;
      Apply(effects, th, &g);
      return -TotalLogLik(d, g);
    };
    Eigen::MatrixXd H(n, n);
    const double h = 1e-4;
    for (size_t i = 0; i < n; ++i)
      for (size_t j = i; j < n; ++j) {
        auto at = [&](double di, double dj) {
          std::vector<double> x = t.theta;
          x[i] += di;
          x[j] += dj;
          return nll(x);
        };
        H(i, j) = H(j, i) = (at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4 * h * h);
      }
    // A parameter driven to the edge of its range (a floor fitted to zero: its log runs
    // off to -infinity) carries no information; the others' errors come from the rest.
    std::vector<int> keep;
    const double dmax = H.diagonal().cwiseAbs().maxCoeff();
    for (size_t i = 0; i < n; ++i)
      if (H(i, i) > 1e-9 * dmax) keep.push_back(static_cast<int>(i));
    Eigen::MatrixXd Hk(keep.size(), keep.size());
    for (size_t i = 0; i < keep.size(); ++i)
      for (size_t j = 0; j < keep.size(); ++j) Hk(i, j) = H(keep[i], keep[j]);
    if (!keep.empty()) {
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Hk);
      if (es.eigenvalues().minCoeff() > 0) {
        const Eigen::MatrixXd C = Hk.inverse();
        for (size_t i = 0; i < keep.size(); ++i) se[keep[i]] = std::sqrt(C(i, i));
      }
    }
  }
  size_t k = 0;
  auto add = [&](const std::string& name, double value, double dvalue_dtheta) {
    f.parameters.push_back({name, value});
    f.standard_errors.push_back({name, std::abs(dvalue_dtheta) * se[k]});
    ++k;
  };
  for (const auto& e : effects) {
    if (e == "pixel_noise_scale") add("scale", f.scale, f.scale);
    else if (e == "noise_floor") add("floor_m", f.floor, f.floor);
    else if (e == "anisotropy_x") add("sigma_x_m", f.anisotropy.x(), f.anisotropy.x());
    else if (e == "anisotropy_y") add("sigma_y_m", f.anisotropy.y(), f.anisotropy.y());
    else if (e == "anisotropy_z") add("sigma_z_m", f.anisotropy.z(), f.anisotropy.z());
    else if (e == "misidentification") {
      const double p = f.outlier_probability;
      add("probability", p, p * (1 - p));
      add("sigma_m", f.outlier_sigma, f.outlier_sigma);
    }
  }
  f.outlier_posterior.assign(d.size(), 0.0);
  if (f.outlier_probability > 0)
    for (size_t i = 0; i < d.size(); ++i) {
      const Vec3 s2 = f.InlierVariance(d.nominal[i]);
      const double a = std::log1p(-f.outlier_probability) + SampleVarianceLogLik(d.measured[i], s2, d.repeats[i]);
      const double b = std::log(f.outlier_probability) +
                       SampleVarianceLogLik(d.measured[i], s2 + Vec3::Constant(f.outlier_sigma * f.outlier_sigma), d.repeats[i]);
      f.outlier_posterior[i] = 1.0 / (1.0 + std::exp(a - b));
    }
  return f;
}

void CheckData(const VarianceData& d) {
  MCMS_CHECK(d.nominal.size() == d.size() && d.repeats.size() == d.size(), "VarianceData: sizes differ");
  for (size_t i = 0; i < d.size(); ++i) {
    MCMS_CHECK(d.nominal[i].minCoeff() > 0 && d.nominal[i].allFinite(), "VarianceData: nominal variances must be positive");
    MCMS_CHECK(d.measured[i].minCoeff() > 0 && d.measured[i].allFinite(), "VarianceData: measured variances must be positive");
    MCMS_CHECK(d.repeats[i] >= 2, "VarianceData: at least 2 repeats per point");
  }
}

}  // namespace

NoiseModelFit FitNoiseModel(const VarianceData& d, const std::vector<std::string>& effects) {
  CheckData(d);
  std::vector<std::vector<double>> starts{InitialTheta(d, effects)};
  return Finish(d, effects, FitTheta(d, effects, starts));
}

NoiseModelFit SelectNoiseModel(const VarianceData& d, const std::vector<std::string>& candidates_in) {
  CheckData(d);
  const std::vector<std::string>& candidates = candidates_in.empty() ? CandidateEffects() : candidates_in;
  std::vector<std::string> chosen;
  const int K = static_cast<int>(candidates.size());
  ThetaFit current = FitTheta(d, chosen, {{}});
  NoiseModelFit best = Finish(d, chosen, current, K);
  std::ostringstream log;
  char buf[256];
  std::snprintf(buf, sizeof(buf), "  nominal: log L = %.2f, EBIC = %.2f\n", best.loglik, best.bic);
  log << buf;
  for (;;) {
    NoiseModelFit step_best;
    ThetaFit step_theta;
    bool any = false;
    for (const auto& c : candidates) {
      if (std::find(chosen.begin(), chosen.end(), c) != chosen.end()) continue;
      std::vector<std::string> trial = chosen;
      trial.push_back(c);
      // Start from the current optimum plus the new effect's own start, and from scratch.
      std::vector<double> warm = current.theta;
      const std::vector<double> fresh = InitialTheta(d, trial);
      for (size_t k = warm.size(); k < fresh.size(); ++k) warm.push_back(fresh[k]);
      std::vector<double> small = warm;
      for (size_t k = current.theta.size(); k < small.size(); ++k)
        if (!(c == "misidentification" && k == current.theta.size())) small[k] -= 2.0;
      const ThetaFit t = FitTheta(d, trial, {warm, small, fresh});
      const NoiseModelFit f = Finish(d, trial, t, K);
      std::snprintf(buf, sizeof(buf), "    + %-18s log L = %10.2f, EBIC = %10.2f\n", c.c_str(), f.loglik, f.bic);
      log << buf;
      if (!any || f.bic < step_best.bic) step_best = f, step_theta = t, any = true;
    }
    if (!any || !(step_best.bic < best.bic)) {
      log << "  stop: no candidate lowers the EBIC\n";
      break;
    }
    std::snprintf(buf, sizeof(buf), "  add %s: EBIC %.2f -> %.2f\n", step_best.effects.back().c_str(), best.bic, step_best.bic);
    log << buf;
    best = step_best;
    current = step_theta;
    chosen = best.effects;
  }
  // Backward: an effect that a later one made redundant (a floor fitted to zero once the
  // pixel-noise scale took its place) is removed while that lowers the EBIC.
  for (bool removed = true; removed && !chosen.empty();) {
    removed = false;
    for (size_t k = 0; k < chosen.size(); ++k) {
      std::vector<std::string> trial;
      for (size_t j = 0; j < chosen.size(); ++j)
        if (j != k) trial.push_back(chosen[j]);
      std::vector<double> warm;
      {
        // The current optimum without the removed effect's parameters.
        size_t at = 0;
        for (size_t j = 0; j < chosen.size(); ++j) {
          const size_t np = chosen[j] == "misidentification" ? 2 : 1;
          if (j != k)
            for (size_t q = 0; q < np; ++q) warm.push_back(current.theta[at + q]);
          at += np;
        }
      }
      const ThetaFit t = FitTheta(d, trial, {warm, InitialTheta(d, trial)});
      const NoiseModelFit f = Finish(d, trial, t, K);
      if (f.bic < best.bic) {
        std::snprintf(buf, sizeof(buf), "  remove %s: EBIC %.2f -> %.2f\n", chosen[k].c_str(), best.bic, f.bic);
        log << buf;
        best = f;
        current = t;
        chosen = trial;
        removed = true;
        break;
      }
    }
  }
  best.selection_log = log.str();
  return best;
}

std::vector<double> HeldOutLogLik(const VarianceData& d, const std::vector<std::string>& effects) {
  CheckData(d);
  const ThetaFit all = FitTheta(d, effects, {InitialTheta(d, effects)});
  std::vector<double> out(d.size());
  for (size_t i = 0; i < d.size(); ++i) {
    const ThetaFit t = FitTheta(d, effects, {all.theta}, i);
    NoiseModelFit f;
    Apply(effects, t.theta, &f);
    out[i] = f.PointLogLik(d.nominal[i], d.measured[i], d.repeats[i]);
  }
  return out;
}

// ---------------------------------------------------------------------------------------
// The analysis

int PaperLayout::first_point_of_plane(int plane, const std::vector<MeasuredPoint>& points) const {
  int first = -1;
  for (size_t i = 0; i < points.size(); ++i)
    if (points[i].plane == plane && (first < 0 || LabelLess(points[i].id, points[first].id))) first = static_cast<int>(i);
  return first;
}

namespace {

double Sum(const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0); }

// Positions of Table 1's points under a layout, in the rig frame. InputError when a plane
// holds more points than the layout has places or the plane number exceeds the layout's.
std::vector<Vec3> LayoutPositions(const MeasuredPoints& m, const PaperLayout& L, const CameraRig& rig) {
  Vec3 centre = Vec3::Zero();
  for (const auto& cam : rig.cameras) centre += cam.T_cam_rig().Inverse().t;
  centre /= static_cast<double>(rig.size());
  static const int perimeter[9][2] = {{-1, -1}, {0, -1}, {1, -1}, {1, 0}, {1, 1}, {0, 1}, {-1, 1}, {-1, 0}, {0, 0}};
  std::map<int, std::vector<size_t>> by_plane;
  for (size_t i = 0; i < m.points.size(); ++i) by_plane[m.points[i].plane].push_back(i);
  std::vector<Vec3> pos(m.points.size());
  for (auto& [plane, idx] : by_plane) {
    if (plane < 1 || plane > L.planes)
      Throw(m.source.string(), ": plane ", plane, " is outside the assumed layout of ", L.planes, " planes");
    if (idx.size() > 9)
      Throw(m.source.string(), ": plane ", plane, " has ", idx.size(), " points; the assumed layout has 9 per plane (3 x 3)");
    std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return LabelLess(m.points[a].id, m.points[b].id); });
    const double D = L.planes > 1 ? L.first_plane_distance_m + (L.last_plane_distance_m - L.first_plane_distance_m) *
                                                                    (plane - 1) / (L.planes - 1)
                                  : L.first_plane_distance_m;
    for (size_t j = 0; j < idx.size(); ++j) {
      const int gx = L.perimeter_numbering ? perimeter[j][0] : static_cast<int>(j % 3) - 1;
      const int gy = L.perimeter_numbering ? perimeter[j][1] : static_cast<int>(j / 3) - 1;
      pos[idx[j]] = Vec3(centre.x() + gx * L.dx_m, centre.y() + gy * L.dy_m, centre.z() - D);
    }
  }
  return pos;
}

struct NominalAt {
  std::vector<Vec3> sigma_rig;  // m
  std::vector<bool> trackable;
  std::vector<double> border_px;
  int untrackable = 0;
};

NominalAt Nominal(const PredictPoints& predict, const std::vector<Vec3>& pos, const std::vector<MeasuredPoint>& pts) {
  const std::vector<PointPrediction> pr = predict(pos);
  if (pr.size() != pos.size()) Throw("fov-map --measured: the prediction gave ", pr.size(), " points for ", pos.size());
  NominalAt n;
  n.sigma_rig.resize(pos.size());
  n.trackable.resize(pos.size());
  for (size_t i = 0; i < pos.size(); ++i) {
    n.border_px.push_back(pr[i].min_border_px);
    n.trackable[i] = pr[i].trackable;
    n.sigma_rig[i] = pr[i].trackable ? pr[i].SigmaPosition() : Vec3::Constant(std::nan(""));
  }
  // A point the nominal rig cannot track takes the prediction of the nearest trackable
  // point (same plane first): the nominal model then says "as elsewhere", not "nothing".
  for (size_t i = 0; i < pos.size(); ++i) {
    if (n.trackable[i]) continue;
    ++n.untrackable;
    double best = INFINITY;
    for (size_t j = 0; j < pos.size(); ++j) {
      if (!n.trackable[j]) continue;
      const double d = (pos[j] - pos[i]).norm() + (pts[j].plane == pts[i].plane ? 0.0 : 100.0);
      if (d < best) best = d, n.sigma_rig[i] = n.sigma_rig[j];
    }
  }
  for (const Vec3& s : n.sigma_rig)
    if (!s.allFinite())
      Throw("fov-map --measured: the nominal rig tracks none of the measured points (at the assumed positions); "
            "give --rig and --grid for the measured rig");
  return n;
}

VarianceData MakeData(const MeasuredPoints& m, const NominalAt& n, const int axis_of_paper[3]) {
  VarianceData d;
  for (size_t i = 0; i < m.points.size(); ++i) {
    Vec3 nom;
    for (int p = 0; p < 3; ++p) nom[p] = n.sigma_rig[i][axis_of_paper[p]] * n.sigma_rig[i][axis_of_paper[p]];
    d.nominal.push_back(nom);
    d.measured.push_back(m.points[i].variance);
    d.repeats.push_back(m.points[i].repeats);
  }
  return d;
}

std::string Join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : " + ") + x;
  return s.empty() ? "(nominal)" : s;
}

std::string ParamLine(const NoiseModelFit& f) {
  std::ostringstream o;
  char b[128];
  for (size_t i = 0; i < f.parameters.size(); ++i) {
    const auto& [name, v] = f.parameters[i];
    const double se = f.standard_errors[i].second;
    const bool metres = name.size() > 2 && name.compare(name.size() - 2, 2, "_m") == 0;
    // A parameter at the edge of its range (a floor fitted to zero) has no finite standard
    // error: the information matrix is singular there.
    if (metres && std::isfinite(se))
      std::snprintf(b, sizeof(b), "%s%s = %.4g +- %.2g mm", i ? ", " : "", name.substr(0, name.size() - 2).c_str(), v * 1e3,
                    se * 1e3);
    else if (metres)
      std::snprintf(b, sizeof(b), "%s%s = %.4g mm (no standard error: at a bound)", i ? ", " : "",
                    name.substr(0, name.size() - 2).c_str(), v * 1e3);
    else if (std::isfinite(se))
      std::snprintf(b, sizeof(b), "%s%s = %.4g +- %.2g", i ? ", " : "", name.c_str(), v, se);
    else
      std::snprintf(b, sizeof(b), "%s%s = %.4g (no standard error: at a bound)", i ? ", " : "", name.c_str(), v);
    o << b;
  }
  return o.str();
}

// Table 2 from the fitted point model. `swap`: the 500 mm lines along y instead of x
// (only for lines without named end points); `m`: repeats averaged per line end.
Table2Prediction PredictLines(const MeasuredReport& R, const MeasuredLines& lines, const PaperLayout& layout, bool swap, int m,
                              const MeasuredAnalysisOptions& opt) {
  Table2Prediction T;
  const MeasuredPoints& measured = R.measured;
  std::ostringstream name;
  name << (swap ? "500 mm lines along y" : "500 mm lines along x") << ", ends averaged over " << m << " repeat" << (m > 1 ? "s" : "");
  T.variant = name.str();
  std::map<std::string, size_t> index_of;
  for (size_t i = 0; i < measured.points.size(); ++i) index_of[measured.points[i].id] = i;
  const double laser2 = 2 * opt.laser_sigma_m * opt.laser_sigma_m;
  // Gross lines: beyond 3 times the largest inlier sd any direction allows (the fit's
  // worst axis at single measurements), so the classification does not depend on the
  // direction assumed.
  double worst = 0;
  for (size_t i = 0; i < R.data.size(); ++i) worst = std::max(worst, R.fit.InlierVariance(R.data.nominal[i]).maxCoeff());
  const double gross = 3 * std::sqrt(2 * worst / std::max(1, opt.repeats_per_line_end) + laser2);
  double sum_abs = 0, sum_pred = 0, sum_var = 0;
  auto lognormal = [](double x, double v) { return -0.5 * std::log(2 * std::numbers::pi * v) - 0.5 * x * x / v; };
  for (const auto& l : lines.lines) {
    LinePrediction lp;
    lp.line = l;
    Vec3 var_a, var_b, nom_a, nom_b;
    double p_out_a = R.fit.outlier_probability, p_out_b = R.fit.outlier_probability;
    if (!l.from.empty()) {
      const auto ia = index_of.find(l.from), ib = index_of.find(l.to);
      if (ia == index_of.end() || ib == index_of.end())
        Throw(lines.source.string(), ": line ", l.id, " of plane ", l.plane, " joins ", l.from, " and ", l.to,
              ", which are not both among the measured points of ", measured.source.string());
      lp.direction = (R.positions_rig[ib->second] - R.positions_rig[ia->second]).normalized();
      var_a = R.fit.InlierVariance(R.data.nominal[ia->second]);
      var_b = R.fit.InlierVariance(R.data.nominal[ib->second]);
      nom_a = R.data.nominal[ia->second];
      nom_b = R.data.nominal[ib->second];
      p_out_a = R.fit.outlier_posterior.empty() ? 0.0 : R.fit.outlier_posterior[ia->second];
      p_out_b = R.fit.outlier_posterior.empty() ? 0.0 : R.fit.outlier_posterior[ib->second];
    } else {
      // End points unknown: the direction from the length (the layout's dx lines along x,
      // dy along y, or swapped), the ends' variance the plane's mean.
      const bool along_x = std::abs(l.d_reference_m - layout.dx_m) <= std::abs(l.d_reference_m - layout.dy_m);
      lp.direction = along_x != swap ? Vec3::UnitX() : Vec3::UnitY();
      Vec3 sum = Vec3::Zero(), sum_nom = Vec3::Zero();
      int n = 0;
      for (int pass = 0; pass < 2 && n == 0; ++pass)
        for (size_t i = 0; i < measured.points.size(); ++i)
          if (pass == 1 || measured.points[i].plane == l.plane)
            sum += R.fit.InlierVariance(R.data.nominal[i]), sum_nom += R.data.nominal[i], ++n;
      var_a = var_b = sum / n;
      nom_a = nom_b = sum_nom / n;
    }
    const Vec3 u2 = lp.direction.cwiseAbs2();
    const double var_in = (u2.dot(var_a) + u2.dot(var_b)) / m + laser2;
    const double var_nom = (u2.dot(nom_a) + u2.dot(nom_b)) / m + laser2;
    const double var_iso = 2 * opt.paper_isotropic_sigma_m * opt.paper_isotropic_sigma_m / m + laser2;
    const double var_out = var_in + 2 * R.fit.outlier_sigma * R.fit.outlier_sigma / m;
    lp.predicted_sd_m = std::sqrt(var_in);
    lp.outlier_probability = 1 - (1 - p_out_a) * (1 - p_out_b);
    const double delta = l.d_reference_m - l.d_measured_m;
    lp.z = delta / lp.predicted_sd_m;
    const double a = std::log1p(-std::min(lp.outlier_probability, 1 - 1e-12)) + lognormal(delta, var_in);
    const double b = lp.outlier_probability > 0 ? std::log(lp.outlier_probability) + lognormal(delta, var_out) : -INFINITY;
    const double mx = std::max(a, b);
    T.loglik_extended += mx + std::log(std::exp(a - mx) + std::exp(b - mx));
    T.loglik_nominal += lognormal(delta, var_nom);
    T.loglik_isotropic += lognormal(delta, var_iso);
    lp.gross = std::abs(delta) > gross;
    if (!lp.gross) {
      ++T.inliers;
      sum_abs += std::abs(delta);
      sum_pred += lp.predicted_sd_m * std::sqrt(2 / std::numbers::pi);
      sum_var += var_in * (1 - 2 / std::numbers::pi);
    }
    T.lines.push_back(lp);
  }
  T.gross_threshold_m = gross;
  if (T.inliers > 0) {
    T.measured_mean_abs_m = sum_abs / T.inliers;
    T.predicted_mean_abs_m = sum_pred / T.inliers;
    T.predicted_mean_abs_sd_m = std::sqrt(sum_var) / T.inliers;
  }
  return T;
}

// The human-readable report of the analysis.
std::string MeasuredText(const MeasuredReport& R, const MeasuredPoints& measured, const MeasuredLines* lines,
                         const CameraRig& rig, int untrackable, const MeasuredAnalysisOptions& opt) {
  std::ostringstream o;
  char b[512];
  o << "\nMeasured repeatability (" << measured.source.string() << ", " << measured.points.size() << " points) against the nominal model\n";
  o << R.layout_text;
  o << "nominal model: the mapped rig and pixel noise (" << rig.size() << " cameras), the target at the same orientation\n";
  if (untrackable > 0)
    o << "  " << untrackable
      << " point(s) cannot be tracked by the nominal rig at the assumed position; they take the nearest trackable point's "
         "prediction\n";
  std::snprintf(b, sizeof(b), "  %-6s %5s %9s %9s %9s   %9s %9s %9s   %9s %9s %9s   %6s\n", "point", "plane", "meas_x", "meas_y",
                "meas_z", "nom_x", "nom_y", "nom_z", "fit_x", "fit_y", "fit_z", "P(out)");
  o << b;
  for (size_t i = 0; i < measured.points.size(); ++i) {
    const auto& p = measured.points[i];
    const Vec3 ms = p.variance.cwiseSqrt() * 1e3, ns = R.data.nominal[i].cwiseSqrt() * 1e3,
               fs = R.fit.InlierVariance(R.data.nominal[i]).cwiseSqrt() * 1e3;
    std::snprintf(b, sizeof(b), "  %-6s %5d %9.4f %9.4f %9.4f   %9.4f %9.4f %9.4f   %9.4f %9.4f %9.4f   %6.3f%s\n", p.id.c_str(),
                  p.plane, ms.x(), ms.y(), ms.z(), ns.x(), ns.y(), ns.z(), fs.x(), fs.y(), fs.z(),
                  R.fit.outlier_posterior.empty() ? 0.0 : R.fit.outlier_posterior[i],
                  !R.fit.outlier_posterior.empty() && R.fit.outlier_posterior[i] > 0.5 ? "  misidentified (outlier)" : "");
    o << b;
  }
  o << "  (sigmas in mm; nom = the nominal prediction, fit = the extended model's inlier sigma)\n";
  {
    // Are the misidentified points at the edge of the view (under the nominal rig)?
    double out_sum = 0, in_sum = 0;
    int n_out = 0, n_in = 0;
    for (size_t i = 0; i < measured.points.size(); ++i) {
      if (!std::isfinite(R.nominal_border_px[i])) continue;
      if (!R.fit.outlier_posterior.empty() && R.fit.outlier_posterior[i] > 0.5) out_sum += R.nominal_border_px[i], ++n_out;
      else in_sum += R.nominal_border_px[i], ++n_in;
    }
    if (n_out > 0 && n_in > 0) {
      std::snprintf(b, sizeof(b),
                    "edge of the view (nominal rig, assumed positions): nearest approach of a ball image to an image border, "
                    "mean %.0f px at the %d misidentified points, %.0f px at the other %d\n",
                    out_sum / n_out, n_out, in_sum / n_in, n_in);
      o << b;
    }
  }
  {
    // Accuracy against the reference (raw measurements with --reference).
    Vec3 sq = Vec3::Zero();
    int n = 0;
    double chi2 = 0;
    for (size_t i = 0; i < measured.points.size(); ++i) {
      const auto& p = measured.points[i];
      if (!p.reference || !p.mean_rig) continue;
      const Vec3 e = *p.mean_rig - *p.reference;
      sq += e.cwiseAbs2();
      // The mean of n repeats against the fitted inlier variance / n.
      chi2 += (e.cwiseAbs2().cwiseQuotient(R.fit.InlierVariance(R.data.nominal[i]) / p.repeats)).sum();
      ++n;
    }
    if (n > 0) {
      const Vec3 rms = (sq / n).cwiseSqrt() * 1e3;
      std::snprintf(b, sizeof(b),
                    "accuracy against the reference (%d points): RMS error of the mean x %.4f, y %.4f, z %.4f, d %.4f mm; "
                    "chi-square against the fitted repeatability %.1f for %d dof (above: errors beyond repeatability)\n",
                    n, rms.x(), rms.y(), rms.z(), rms.norm(), chi2, 3 * n);
      o << b;
    }
  }
  o << "greedy selection by the extended BIC (BIC + 2 ln C(candidates, effects); N = " << R.fit.num_variances << " sample variances):\n" << R.fit.selection_log;
  o << "selected: " << Join(R.fit.effects) << "\n  " << ParamLine(R.fit) << "\n";
  std::snprintf(b, sizeof(b),
                "log likelihood: nominal %.1f, paper's isotropic %.3f mm %.1f, extended %.1f (in sample)\n"
                "held out (leave one point out, summed): extended %.1f; gain over nominal %.1f, over isotropic %.1f (natural log)\n",
                R.loglik_nominal, opt.paper_isotropic_sigma_m * 1e3, R.loglik_isotropic, R.fit.loglik, Sum(R.heldout_extended),
                R.heldout_gain, R.heldout_gain_vs_isotropic);
  o << b;
  if (!R.sensitivity.empty()) {
    o << "dependence on the assumed layout (each refitted and selected again):\n";
    for (const auto& s : R.sensitivity) {
      std::snprintf(b, sizeof(b), "  %-46s %-62s held-out gain %.1f (vs isotropic %.1f)%s\n", s.layout.c_str(), Join(s.effects).c_str(),
                    s.heldout_gain, s.heldout_gain_vs_isotropic,
                    s.untrackable_nominal ? (" [" + std::to_string(s.untrackable_nominal) + " untrackable]").c_str() : "");
      o << b << "      " << s.parameters << "\n";
    }
  }
  {
    // What the data cannot decide: each selected effect dropped in turn (refitted); a
    // small loss of log likelihood means another effect takes its place. With two planes a
    // floor and a scaled pixel noise differ only through the nominal model's change of
    // sigma between the assumed plane distances.
    o << "each selected effect dropped in turn (log L lost; < 2 = not decided by these data):";
    for (const auto& drop : R.fit.effects) {
      std::vector<std::string> rest;
      for (const auto& x : R.fit.effects)
        if (x != drop) rest.push_back(x);
      const NoiseModelFit fa = FitNoiseModel(R.data, rest);
      std::snprintf(b, sizeof(b), " %s %.1f;", drop.c_str(), R.fit.loglik - fa.loglik);
      o << b;
    }
    o << "\n";
    // A distance-independent floor against a scaled pixel noise (which grows with the
    // distance as the nominal sigma does): with two planes only the nominal model's change
    // between the assumed plane distances tells them apart.
    const std::vector<std::string>& e = R.fit.effects;
    const bool has_floor = std::find(e.begin(), e.end(), "noise_floor") != e.end();
    const bool has_scale = std::find(e.begin(), e.end(), "pixel_noise_scale") != e.end();
    if (has_floor != has_scale) {
      std::vector<std::string> alt;
      for (const auto& x : e) alt.push_back(x == "noise_floor" ? "pixel_noise_scale" : x == "pixel_noise_scale" ? "noise_floor" : x);
      const NoiseModelFit fa = FitNoiseModel(R.data, alt);
      std::snprintf(b, sizeof(b),
                    "%s in place of %s: log L lower by %.1f (%s by these two planes)\n", has_floor ? "pixel_noise_scale" : "noise_floor",
                    has_floor ? "noise_floor" : "pixel_noise_scale", R.fit.loglik - fa.loglik,
                    R.fit.loglik - fa.loglik < 2 ? "not decided" : "decided");
      o << b;
    }
  }
  if (lines) {
    auto line2 = [&](const Table2Prediction& t) {
      std::snprintf(b, sizeof(b),
                    "  %-48s mean |delta| predicted %.3f +- %.3f mm; log L of all deltas: extended %.1f, nominal %.1f, "
                    "isotropic %.1f\n",
                    t.variant.c_str(), t.predicted_mean_abs_m * 1e3, t.predicted_mean_abs_sd_m * 1e3, t.loglik_extended,
                    t.loglik_nominal, t.loglik_isotropic);
      o << b;
    };
    std::snprintf(b, sizeof(b),
                  "Table 2 (%zu lines) predicted from the fit of the points (laser %.3f mm per length): %d lines within %.2f mm "
                  "(3 x the largest inlier sd), their mean |delta| measured %.3f mm (the paper's average over all planes: "
                  "0.478 mm)\n",
                  lines->lines.size(), opt.laser_sigma_m * 1e3, R.table2.inliers, R.table2.gross_threshold_m * 1e3,
                  R.table2.measured_mean_abs_m * 1e3);
    o << b;
    line2(R.table2);
    o << "  alternatives (the paper names no end points and no averaging):\n";
    for (const auto& t : R.table2_variants) line2(t);
  }
  if (!R.lab.empty()) {
    o << "the paper's lab experiment (section 3.4; forward model: 76 points, 7 s dwells, KR 5 arc, inclinometer) with the "
         "camera error drawn from each model instead of rendering (three-sigma rule, mm; reductions relative to the camera, "
         "mean +- sd over "
      << R.lab.front().seeds << " draws; the paper: ";
    std::snprintf(b, sizeof(b), "MOIFA %.1f %%, KF %.1f %%, camera %.3f mm):\n", 100 * PaperLabResult::moifa_reduction,
                  100 * PaperLabResult::kf_reduction, 1e3 * PaperLabResult::camera_3sigma_m);
    o << b;
    {
      // What two independent isotropic errors of the paper's sizes allow at best.
      const double c = 1e3 * PaperLabResult::camera_3sigma_m, r = 1e3 * PaperLabResult::robot_3sigma_m,
                   f = 1.0 / std::sqrt(1.0 / (c * c) + 1.0 / (r * r));
      std::snprintf(b, sizeof(b),
                    "  (two independent isotropic errors of the paper's camera %.3f and robot %.3f mm fuse at best to %.3f mm, "
                    "a %.1f %% reduction)\n",
                    c, r, f, 100 * (1 - f / c));
      o << b;
    }
    for (const auto& l : R.lab) {
      std::snprintf(b, sizeof(b), "  %-58s camera %.3f  robot %.3f  MOIFA %.3f (%.1f +- %.1f %%)  KF %.3f (%.1f +- %.1f %%)\n",
                    l.camera_model.c_str(), l.camera_3sigma_m * 1e3, l.robot_3sigma_m * 1e3, l.moifa_3sigma_m * 1e3,
                    100 * l.moifa_reduction, 100 * l.moifa_reduction_sd, l.kf_3sigma_m * 1e3, 100 * l.kf_reduction,
                    100 * l.kf_reduction_sd);
      o << b;
    }
  }
  return o.str();
}

}  // namespace

CameraErrorModel CameraErrorModelFromFit(const NoiseModelFit& fit, const std::string& name, const std::string& source) {
  CameraErrorModel m;
  m.name = name;
  m.source = source;
  m.pixel_noise_scale = fit.scale;
  m.floor_m = std::abs(fit.floor);
  m.anisotropy_m = fit.anisotropy.cwiseAbs();
  return m;
}

bool MeasuredAnalysisOptions::IsValid(std::string* why) const {
  std::string w;
  const auto positive = [&](double v, const char* name, double hi) {
    if (w.empty() && !(v > 0 && v <= hi)) w = std::string(name) + " must be positive and at most " + std::to_string(hi) + ", is " + std::to_string(v);
  };
  positive(plane_first_distance_m, "plane_first_distance_m", kMaxRigRangeM);
  positive(plane_last_distance_m, "plane_last_distance_m", kMaxRigRangeM);
  positive(paper_isotropic_sigma_m, "paper_isotropic_sigma_m", 1.0);
  positive(laser_sigma_m, "laser_sigma_m", 1.0);
  if (w.empty() && (repeats_per_line_end < 1 || repeats_per_line_end > 1000))
    w = "repeats_per_line_end must be 1 to 1000, is " + std::to_string(repeats_per_line_end);
  if (w.empty() && (lab_seeds < 0 || lab_seeds > 1000)) w = "lab_seeds must be 0 to 1000, is " + std::to_string(lab_seeds);
  if (why && !w.empty()) *why = w;
  return w.empty();
}

MeasuredReport AnalyseMeasured(const MeasuredPoints& measured, const MeasuredLines* lines, const CameraRig& rig,
                               const PredictPoints& predict, const PredictLab& lab, const MeasuredAnalysisOptions& opt) {
  if (std::string why; !opt.IsValid(&why)) Throw("measured analysis options: ", why);
  MeasuredReport R;
  R.measured = measured;
  const bool have_positions =
      std::all_of(measured.points.begin(), measured.points.end(), [](const MeasuredPoint& p) { return p.mean_rig.has_value(); });
  PaperLayout layout;
  layout.first_plane_distance_m = opt.plane_first_distance_m;
  layout.last_plane_distance_m = opt.plane_last_distance_m;
  std::ostringstream lt;
  if (have_positions) {
    for (const auto& p : measured.points) R.positions_rig.push_back(*p.mean_rig);
    lt << "point positions: the measured means, taken to be in the rig frame of the mapped rig\n";
  } else {
    R.positions_rig = LayoutPositions(measured, layout, rig);
    lt << "point positions ASSUMED (the table gives none): " << layout.planes << " horizontal planes, plane 1 at "
       << layout.first_plane_distance_m << " m and plane " << layout.planes << " at " << layout.last_plane_distance_m
       << " m below the cameras' mean height, evenly spaced; per plane a 3 x 3 grid " << layout.dx_m * 1e3 << " mm apart in x and "
       << layout.dy_m * 1e3
       << " mm in y (Table 2's 500 and 400 mm lines) centred under the rig, points numbered around the perimeter from a "
          "corner (odd = corner), the centre last; the paper's x, y, z are the rig's x, y, z (z vertical)\n";
  }
  R.layout_text = lt.str();
  const NominalAt nominal = Nominal(predict, R.positions_rig, measured.points);
  R.nominal_sigma = nominal.sigma_rig;
  R.nominal_trackable = nominal.trackable;
  R.nominal_border_px = nominal.border_px;
  R.data = MakeData(measured, nominal, layout.axis_of_paper);
  R.fit = SelectNoiseModel(R.data);

  // Held out.
  R.heldout_extended = HeldOutLogLik(R.data, R.fit.effects);
  NoiseModelFit nom, iso;
  VarianceData iso_data = R.data;
  for (auto& v : iso_data.nominal) v = Vec3::Constant(opt.paper_isotropic_sigma_m * opt.paper_isotropic_sigma_m);
  for (size_t i = 0; i < R.data.size(); ++i) {
    R.heldout_nominal.push_back(nom.PointLogLik(R.data.nominal[i], R.data.measured[i], R.data.repeats[i]));
    R.heldout_isotropic.push_back(nom.PointLogLik(iso_data.nominal[i], R.data.measured[i], R.data.repeats[i]));
  }
  R.loglik_nominal = Sum(R.heldout_nominal);
  R.loglik_isotropic = Sum(R.heldout_isotropic);
  R.heldout_gain = Sum(R.heldout_extended) - R.loglik_nominal;
  R.heldout_gain_vs_isotropic = Sum(R.heldout_extended) - R.loglik_isotropic;

  // The paper's lab experiment with the fitted camera (and the nominal one beside it).
  if (opt.lab_seeds > 0 && lab) {
    const std::vector<PointPrediction> centre = predict({Vec3(0.0, 0.0, 0.5)});
    if (centre[0].trackable) R.lab = lab(CameraErrorModelFromFit(R.fit, "fitted", "this fit"), centre[0].cov,
                                   opt.lab_seeds);
  }

  // How much the conclusion depends on the layout (Table 1 only).
  if (!have_positions && opt.sensitivity) {
    std::vector<PaperLayout> variants;
    PaperLayout v = layout;
    v.name = "assumed";
    variants.push_back(v);
    v = layout, v.name = "planes at 2.2 and 1.2 m (slant range)", v.first_plane_distance_m += 0.2, v.last_plane_distance_m += 0.2;
    variants.push_back(v);
    v = layout, v.name = "planes at 2.0 and 1.5 m", v.last_plane_distance_m = 1.5;
    variants.push_back(v);
    v = layout, v.name = "points numbered row by row", v.perimeter_numbering = false;
    variants.push_back(v);
    v = layout, v.name = "paper y = rig z (vertical), paper z = rig y", v.axis_of_paper[1] = 2, v.axis_of_paper[2] = 1;
    variants.push_back(v);
    for (const auto& L : variants) {
      LayoutResult lr;
      lr.layout = L.name;
      const std::vector<Vec3> pos = LayoutPositions(measured, L, rig);
      const NominalAt n = Nominal(predict, pos, measured.points);
      const VarianceData d = MakeData(measured, n, L.axis_of_paper);
      const NoiseModelFit f = SelectNoiseModel(d);
      const std::vector<double> h = HeldOutLogLik(d, f.effects);
      double ln = 0, li = 0;
      for (size_t i = 0; i < d.size(); ++i) {
        ln += nom.PointLogLik(d.nominal[i], d.measured[i], d.repeats[i]);
        li += nom.PointLogLik(iso_data.nominal[i], d.measured[i], d.repeats[i]);
      }
      lr.effects = f.effects;
      lr.heldout_gain = Sum(h) - ln;
      lr.heldout_gain_vs_isotropic = Sum(h) - li;
      lr.parameters = ParamLine(f);
      lr.untrackable_nominal = n.untrackable;
      R.sensitivity.push_back(lr);
    }
  }

  // Table 2 predicted from the fit of Table 1, under the assumed line directions and
  // averaging, and under the alternatives.
  if (lines) {
    R.table2 = PredictLines(R, *lines, layout, false, opt.repeats_per_line_end, opt);
    for (bool swap : {false, true})
      for (int m : {opt.repeats_per_line_end, 1}) {
        if (!swap && m == opt.repeats_per_line_end) continue;
        R.table2_variants.push_back(PredictLines(R, *lines, layout, swap, m, opt));
      }
  }

  R.text = MeasuredText(R, measured, lines, rig, nominal.untrackable, opt);
  return R;
}

}  // namespace mcms
