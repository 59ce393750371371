#include "audit/inclinometer_audit.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <numeric>

#include <ceres/ceres.h>
#include <ceres/dynamic_autodiff_cost_function.h>

#include "core/error.h"
#include "core/io.h"
#include "core/statistics.h"
#include "core/svg_plot.h"
#include "audit/model_selection.h"

namespace mcms {

bool InclinometerAuditOptions::IsValid(std::string* why) const {
  const auto fail = [&](const char* w) {
    if (why) *why = w;
    return false;
  };
  if (!(false_alarm > 0 && false_alarm < 0.5)) return fail("false_alarm must be in (0, 0.5)");
  if (folds < 2) return fail("folds must be at least 2");
  if (max_effects < 0) return fail("max_effects must be >= 0");
  return true;
}

OrientationReference CameraOrientationReference(const CellGeometry& cell, double time_s, const Pose& T_rig_target,
                                                const Mat6& covariance_rig, int line) {
  const PoseWithCovariance f = CameraFlangePose(cell, T_rig_target, covariance_rig);
  OrientationReference r;
  r.time_s = time_s;
  r.R_base_flange = f.T.R;
  r.covariance = f.covariance.topLeftCorner<3, 3>();
  r.line = line;
  return r;
}

Inclinometer InclinometerAuditResult::Extended(const Inclinometer& nominal) const {
  Inclinometer out = nominal;
  for (size_t k = 0; k < extensions.size(); ++k) {
    const std::vector<double>& p = parameters[k];
    if (extensions[k].effect == Effect::kInclinometerBias) out.bias += Vec2(p[0], p[1]);
    if (extensions[k].effect == Effect::kInclinometerMisalignment)
      out.R_flange_incl = ExpSO3(Vec3(p[0], p[1], p[2])) * out.R_flange_incl;
  }
  return out;
}

namespace {

constexpr double kLog2Pi = 1.8378770664093453;

struct Model {
  std::vector<Extension> ext;
  std::vector<std::vector<double>> p;
  std::vector<std::vector<bool>> held;
  int NumFree() const {
    int n = 0;
    for (const auto& h : held)
      for (bool b : h) n += !b;
    return n;
  }
  const Extension* Clock(int* k = nullptr) const {
    for (size_t i = 0; i < ext.size(); ++i)
      if (ext[i].effect == Effect::kClockOffset || ext[i].effect == Effect::kClockDrift) {
        if (k) *k = static_cast<int>(i);
        return &ext[i];
      }
    return nullptr;
  }
};

// One group: the readings between reference frames a and a + 1.
struct Group {
  int a = 0;                 // index of the first reference frame
  std::vector<int> readings; // indices of the readings
  int fold = 0;
};

// A group's residual set-up under a model: the cost's whitening and its log-determinant.
struct GroupUse {
  Eigen::MatrixXd whitening;
  double logdet = 0.0;
  std::vector<double> w;  // interpolation weights of the readings
  std::vector<int> seg;   // the motion's segment of each reading (-1: none)
};

class Auditor {
 public:
  Auditor(const Inclinometer& incl, const std::vector<OrientationReference>& ref,
          const std::vector<InclinometerReadingSample>& readings, const InclinometerAuditOptions& o,
          const std::vector<OrientationSample>& motion)
      : incl_(incl), ref_(ref), o_(o), motion_(motion) {
    // Saturated readings are not readings.
    const double lim = incl.range + 5 * incl.sigma;
    for (const auto& r : readings)
      if (r.reading.allFinite() && (r.reading - incl.bias).cwiseAbs().maxCoeff() <= lim) z_.push_back(r);
    if (!z_.empty()) t0_ = z_.front().time_s;
    std::vector<double> dt;
    for (size_t i = 1; i < ref.size(); ++i) dt.push_back(ref[i].time_s - ref[i - 1].time_s);
    double max_gap = 0;
    if (!dt.empty()) max_gap = 3.0 * SelectedMedian(dt);
    size_t next = 0;  // first reading not yet before the pair
    for (size_t k = 0; k + 1 < ref.size();) {
      const double ta = ref[k].time_s, tb = ref[k + 1].time_s;
      if (!(tb > ta) || tb - ta > max_gap || incl.Tilt(ref[k].R_base_flange).cwiseAbs().maxCoeff() > incl.range ||
          incl.Tilt(ref[k + 1].R_base_flange).cwiseAbs().maxCoeff() > incl.range) {
        ++k;
        continue;
      }
      Group g;
      g.a = static_cast<int>(k);
      while (next < z_.size() && z_[next].time_s < ta) ++next;
      for (size_t i = next; i < z_.size() && z_[i].time_s < tb; ++i) g.readings.push_back(static_cast<int>(i));
      if (g.readings.empty()) {
        ++k;
        continue;
      }
      groups_.push_back(g);
      k += 2;  // no frame in two groups
    }
    const long n = static_cast<long>(groups_.size());
    for (long i = 0; i < n; ++i) groups_[i].fold = TimeBlockFold(i, n, o.folds);
    for (const Group& g : groups_) num_readings_ += static_cast<long>(g.readings.size());
  }

  long NumReadings() const { return num_readings_; }
  size_t NumGroups() const { return groups_.size(); }
  const std::vector<Group>& Groups() const { return groups_; }
  const OrientationReference& Ref(int k) const { return ref_[k]; }
  const InclinometerReadingSample& Reading(int i) const { return z_[i]; }

  // The motion at t (identity without one) and its segment.
  int Segment(double t) const {
    if (motion_.size() < 2) return -1;
    const auto it = std::upper_bound(motion_.begin(), motion_.end(), t,
                                     [](double x, const OrientationSample& m) { return x < m.time_s; });
    return std::clamp(static_cast<int>(it - motion_.begin()) - 1, 0, static_cast<int>(motion_.size()) - 2);
  }
  Mat3 MotionAt(double t, int seg) const {
    if (seg < 0) return Mat3::Identity();
    const OrientationSample &a = motion_[seg], &b = motion_[seg + 1];
    const double u = (t - a.time_s) / (b.time_s - a.time_s);
    return a.R_base_flange * ExpSO3(u * LogSO3(a.R_base_flange.transpose() * b.R_base_flange));
  }
  // D_a and chi of a group.
  void Discrepancy(const Group& g, Mat3* D_a, Vec3* chi) const {
    const OrientationReference &a = ref_[g.a], &b = ref_[g.a + 1];
    *D_a = MotionAt(a.time_s, Segment(a.time_s)).transpose() * a.R_base_flange;
    const Mat3 D_b = MotionAt(b.time_s, Segment(b.time_s)).transpose() * b.R_base_flange;
    *chi = LogSO3(D_a->transpose() * D_b);
  }

  // `use` (null: the nominal clock, no whitening).
  InclinometerGroupCost Cost(const Model& m, const Group& g, const GroupUse* use) const {
    InclinometerGroupCost c;
    c.incl = &incl_;
    c.ext = &m.ext;
    c.t0 = t0_;
    c.t_a = ref_[g.a].time_s;
    c.t_b = ref_[g.a + 1].time_s;
    Discrepancy(g, &c.D_a, &c.chi);
    for (size_t i = 0; i < g.readings.size(); ++i) {
      const InclinometerReadingSample& zi = z_[g.readings[i]];
      c.s.push_back(zi.time_s);
      c.z.push_back(zi.reading);
      const int seg = use ? use->seg[i] : Segment(zi.time_s);
      if (seg >= 0) {
        const OrientationSample &a = motion_[seg], &b = motion_[seg + 1];
        c.m_t0.push_back(a.time_s);
        c.m_t1.push_back(b.time_s);
        c.m_R0.push_back(a.R_base_flange);
        c.m_psi.push_back(LogSO3(a.R_base_flange.transpose() * b.R_base_flange));
      }
    }
    c.whitening = use ? use->whitening : Eigen::MatrixXd::Identity(c.NumResiduals(), c.NumResiduals());
    return c;
  }

  // The reference orientation of reading i of group g at reference time t (for plots and
  // the whitening).
  Mat3 OrientationAt(const Group& g, double t) const {
    Mat3 D_a;
    Vec3 chi;
    Discrepancy(g, &D_a, &chi);
    const double w = (t - ref_[g.a].time_s) / (ref_[g.a + 1].time_s - ref_[g.a].time_s);
    return MotionAt(t, Segment(t)) * D_a * ExpSO3(w * chi);
  }

  // The groups' whitening under model m's clock.
  std::vector<GroupUse> Assign(const Model& m) const {
    std::vector<GroupUse> out(groups_.size());
    int kc = -1;
    const Extension* clock = m.Clock(&kc);
    Eigen::Matrix<double, 2, 3> H;
    for (size_t gi = 0; gi < groups_.size(); ++gi) {
      const Group& g = groups_[gi];
      const OrientationReference &a = ref_[g.a], &b = ref_[g.a + 1];
      const int n = static_cast<int>(g.readings.size());
      Eigen::MatrixXd A(2 * n, 3), B(2 * n, 3);
      GroupUse& u = out[gi];
      for (int i = 0; i < n; ++i) {
        const double s = z_[g.readings[i]].time_s;
        const double t = clock ? ReferenceTimeT<double>(*clock, m.p[kc].data(), s, t0_) : s;
        const double w = (t - a.time_s) / (b.time_s - a.time_s);
        u.w.push_back(w);
        u.seg.push_back(Segment(t));
        incl_.Tilt(OrientationAt(g, t), &H);
        A.middleRows<2>(2 * i) = (1 - w) * H;
        B.middleRows<2>(2 * i) = w * H;
      }
      const Eigen::MatrixXd S = incl_.sigma * incl_.sigma * Eigen::MatrixXd::Identity(2 * n, 2 * n) +
                                A * a.covariance * A.transpose() + B * b.covariance * B.transpose();
      const Eigen::LLT<Eigen::MatrixXd> llt(S);
      const Eigen::MatrixXd L = llt.matrixL();
      u.whitening = L.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(2 * n, 2 * n));
      u.logdet = 2.0 * L.diagonal().array().log().sum();
    }
    return out;
  }

  Eigen::VectorXd Residual(const Model& m, const Group& g, const GroupUse* use) const {
    const InclinometerGroupCost c = Cost(m, g, use);
    std::vector<const double*> b;
    for (const auto& p : m.p) b.push_back(p.data());
    Eigen::VectorXd r(c.NumResiduals());
    c(b.data(), r.data());
    return r;
  }

  // Least squares over the groups outside `fold` (-1: all), the free parameters of m.
  Model Fit(Model m, int fold) const {
    if (m.NumFree() == 0) return m;
    const int passes = m.Clock() ? 2 : 1;
    for (int pass = 0; pass < passes; ++pass) {
      const std::vector<GroupUse> use = Assign(m);
      ceres::Problem::Options po;
      po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
      ceres::Problem problem(po);
      std::vector<double*> blocks;
      for (auto& p : m.p) blocks.push_back(p.data());
      for (size_t gi = 0; gi < groups_.size(); ++gi) {
        if (fold >= 0 && groups_[gi].fold == fold) continue;
        auto* f = new InclinometerGroupCost(Cost(m, groups_[gi], &use[gi]));
        f->ext = &m.ext;
        auto* cf = new ceres::DynamicAutoDiffCostFunction<InclinometerGroupCost, 4>(f);
        for (const auto& p : m.p) cf->AddParameterBlock(static_cast<int>(p.size()));
        cf->SetNumResiduals(f->NumResiduals());
        problem.AddResidualBlock(cf, nullptr, blocks);
      }
      for (size_t k = 0; k < m.p.size(); ++k) {
        std::vector<int> held;
        for (size_t j = 0; j < m.held[k].size(); ++j)
          if (m.held[k][j]) held.push_back(static_cast<int>(j));
        if (held.size() == m.p[k].size()) problem.SetParameterBlockConstant(blocks[k]);
        else if (!held.empty())
          problem.SetManifold(blocks[k], new ceres::SubsetManifold(static_cast<int>(m.p[k].size()), held));
      }
      ceres::Solver::Options so;
      so.linear_solver_type = ceres::DENSE_QR;
      so.max_num_iterations = 50;
      so.function_tolerance = 1e-12;
      so.parameter_tolerance = 1e-12;
      so.num_threads = 1;
      ceres::Solver::Summary sum;
      ceres::Solve(so, &problem, &sum);
    }
    return m;
  }

  struct Eval {
    double chi2 = 0, logdet = 0, sq = 0;
    long n = 0;  // readings
  };
  // Over the groups in `fold` (in_fold) or outside it (-1: all).
  Eval Evaluate(const Model& m, int fold, bool in_fold) const {
    Eval e;
    const std::vector<GroupUse> use = Assign(m);
    for (size_t gi = 0; gi < groups_.size(); ++gi) {
      const Group& g = groups_[gi];
      if (fold >= 0 && (g.fold == fold) != in_fold) continue;
      e.chi2 += Residual(m, g, &use[gi]).squaredNorm();
      e.logdet += use[gi].logdet;
      e.sq += Residual(m, g, nullptr).squaredNorm();
      e.n += static_cast<long>(g.readings.size());
    }
    return e;
  }
  static double LogLik(const Eval& e, double s2) {
    return -0.5 * (e.chi2 / s2 + 2.0 * e.n * std::log(s2) + e.logdet + 2.0 * e.n * kLog2Pi);
  }
  static double Scale2(const Eval& e) { return e.n > 0 ? std::max(1e-30, e.chi2 / (2.0 * e.n)) : 1.0; }

  // Profiled log-likelihood on all data.
  double LogLikAll(const Model& m) const {
    const Eval e = Evaluate(m, -1, false);
    return LogLik(e, Scale2(e));
  }
  // Held-out log-likelihood and RMS (rad) over the folds.
  void CrossValidate(const Model& m, double* ll, double* rms) const {
    double sum = 0, sq = 0;
    long n = 0;
    for (int f = 0; f < o_.folds; ++f) {
      const Model fit = Fit(m, f);
      const double s2 = Scale2(Evaluate(fit, f, false));
      const Eval e = Evaluate(fit, f, true);
      sum += LogLik(e, s2);
      sq += e.sq;
      n += e.n;
    }
    *ll = sum;
    *rms = n > 0 ? std::sqrt(sq / (2.0 * n)) : 0.0;
  }

  // Whitened Jacobian (every residual x all parameters).
  Eigen::MatrixXd Jacobian(const Model& m) const {
    int P = 0;
    for (const auto& p : m.p) P += static_cast<int>(p.size());
    const std::vector<GroupUse> use = Assign(m);
    Eigen::MatrixXd J(2 * num_readings_, P);
    std::vector<const double*> b;
    for (const auto& p : m.p) b.push_back(p.data());
    long row = 0;
    for (size_t gi = 0; gi < groups_.size(); ++gi) {
      auto* f = new InclinometerGroupCost(Cost(m, groups_[gi], &use[gi]));
      const int nr = f->NumResiduals();
      ceres::DynamicAutoDiffCostFunction<InclinometerGroupCost, 4> cf(f);
      for (const auto& p : m.p) cf.AddParameterBlock(static_cast<int>(p.size()));
      cf.SetNumResiduals(nr);
      std::vector<std::vector<double>> jb(m.p.size());
      std::vector<double*> jp;
      for (size_t k = 0; k < m.p.size(); ++k) {
        jb[k].resize(nr * m.p[k].size());
        jp.push_back(jb[k].data());
      }
      Eigen::VectorXd r(nr);
      cf.Evaluate(b.data(), r.data(), jp.data());
      int col = 0;
      for (size_t k = 0; k < m.p.size(); ++k) {
        const int np = static_cast<int>(m.p[k].size());
        for (int a = 0; a < nr; ++a)
          for (int c2 = 0; c2 < np; ++c2) J(row + a, col + c2) = jb[k][a * np + c2];
        col += np;
      }
      row += nr;
    }
    return J;
  }

 private:
  const Inclinometer& incl_;
  const std::vector<OrientationReference>& ref_;
  const InclinometerAuditOptions& o_;
  const std::vector<OrientationSample> motion_;  // a copy: the caller may pass a temporary
  std::vector<InclinometerReadingSample> z_;
  std::vector<Group> groups_;
  long num_readings_ = 0;
  double t0_ = 0.0;
};

std::vector<int> FreeColumns(const Model& m) {
  std::vector<int> cols;
  int col = 0;
  for (const auto& h : m.held)
    for (bool b : h) {
      if (!b) cols.push_back(col);
      ++col;
    }
  return cols;
}

// Holds the parameters of the last block of m whose columns depend on the free ones
// before them (not identifiable from these data); returns the number left free.
int HoldUnidentifiable(const Auditor& a, Model* m) {
  const Eigen::MatrixXd J = a.Jacobian(*m);
  const int last = static_cast<int>(m->p.size()) - 1;
  int first_col = 0;
  for (int k = 0; k < last; ++k) first_col += static_cast<int>(m->p[k].size());
  Eigen::MatrixXd Q(J.rows(), 0);
  for (int c : FreeColumns(*m)) {
    const bool in_last = c >= first_col;
    Eigen::VectorXd v = J.col(c);
    const double nv = v.norm();
    for (int i = 0; i < Q.cols(); ++i) v -= Q.col(i) * Q.col(i).dot(v);
    if (!(nv > 0) || v.norm() < 1e-6 * nv) {
      if (in_last) m->held[last][c - first_col] = true;
      continue;
    }
    Q.conservativeResize(Eigen::NoChange, Q.cols() + 1);
    Q.col(Q.cols() - 1) = v / v.norm();
  }
  int free = 0;
  for (bool b : m->held[last]) free += !b;
  return free;
}


// The nominal model's residual tests: chi-square against the setup's sigma, lag-1
// autocorrelation in time, trends against time, tilt and tilt rate, per axis.
void TestNominalResiduals(const Auditor& a, const Inclinometer& incl, const Model& cur, const Auditor::Eval& ev0,
                          long N, double alpha_tests, const std::string& where, AuditReport* rep_out) {
  AuditReport& rep = *rep_out;
  std::vector<AuditTest> tests;
  const double p_hi = ChiSquareSurvival(ev0.chi2, 2.0 * N);
  const double p_lo = ChiSquareCdf(ev0.chi2, 2.0 * N);
  tests.push_back({where + ": chi-square of the residuals against its sigma (chi2/dof)", rep.nominal_chi2_per_dof,
                   std::min(1.0, 2 * std::min(p_hi, p_lo)), false});
  std::vector<std::vector<double>> w(2);
  std::vector<std::pair<std::string, std::vector<double>>> cov(5);
  cov[0].first = "time";
  cov[1].first = "tilt x";
  cov[2].first = "tilt y";
  cov[3].first = "tilt rate x";
  cov[4].first = "tilt rate y";
  const std::vector<GroupUse> use = a.Assign(cur);
  for (size_t gi = 0; gi < a.NumGroups(); ++gi) {
    const Group& g = a.Groups()[gi];
    const Eigen::VectorXd r = a.Residual(cur, g, &use[gi]);
    const OrientationReference &ra = a.Ref(g.a), &rb = a.Ref(g.a + 1);
    // The tilt rate from the frames, not the readings (whose noise is in the residual).
    const Vec2 rate = (incl.Tilt(rb.R_base_flange) - incl.Tilt(ra.R_base_flange)) / (rb.time_s - ra.time_s);
    for (size_t i = 0; i < g.readings.size(); ++i) {
      w[0].push_back(r[2 * i]);
      w[1].push_back(r[2 * i + 1]);
      const Vec2 tilt = incl.Tilt(a.OrientationAt(g, a.Reading(g.readings[i]).time_s));
      cov[0].second.push_back(a.Reading(g.readings[i]).time_s);
      cov[1].second.push_back(tilt[0]);
      cov[2].second.push_back(tilt[1]);
      cov[3].second.push_back(rate[0]);
      cov[4].second.push_back(rate[1]);
    }
  }
  const char* ax[2] = {"x", "y"};
  for (int k = 0; k < 2; ++k) {
    tests.push_back(AutocorrelationTest(where + ": autocorrelation in time (" + ax[k] + ")", w[k]));
    for (const auto& [name, x] : cov)
      if (auto t = TrendTest(where + ": trend vs " + name + " (" + ax[k] + ")", x, w[k])) tests.push_back(*t);
  }
  const double per = alpha_tests / tests.size();
  for (auto& t : tests) t.failed = t.p_value < per;
  std::stable_sort(tests.begin(), tests.end(),
                   [](const AuditTest& x, const AuditTest& y) { return x.p_value < y.p_value; });
  for (const auto& t : tests)
    if (t.failed || rep.tests.size() < 3) rep.tests.push_back(t);
  char b[200];
  std::snprintf(b, sizeof b,
                "%s: %ld readings between %zu pairs of reference frames, %zu residual tests at a family-wise rate "
                "%.3g (each at %.3g)",
                where.c_str(), N, a.NumGroups(), tests.size(), alpha_tests, per);
  rep.notes.push_back(b);
}

// Sizes and sigmas of the final model, cov = s^2 (J^T J)^-1 over the free parameters, into
// the named effects (a clock_offset later extended to clock_drift is reported once, as
// clock_drift); returns the sigmas per extension.
std::vector<std::vector<double>> SizesOfFinalModel(const Auditor& a, const Model& cur, InclinometerAuditResult* res_out) {
  InclinometerAuditResult& res = *res_out;
  AuditReport& rep = res.report;
  const auto evf = a.Evaluate(cur, -1, false);
  const double s2 = Auditor::Scale2(evf);
  res.noise_scale = std::sqrt(s2);
  std::vector<std::vector<double>> sig(cur.p.size());
  if (cur.NumFree() > 0) {
    const Eigen::MatrixXd J = a.Jacobian(cur);
    const std::vector<int> cols = FreeColumns(cur);
    Eigen::MatrixXd Jf(J.rows(), cols.size());
    for (size_t c = 0; c < cols.size(); ++c) Jf.col(c) = J.col(cols[c]);
    const Eigen::MatrixXd C = s2 * (Jf.transpose() * Jf).completeOrthogonalDecomposition().pseudoInverse();
    int at = 0;
    for (size_t k = 0; k < cur.p.size(); ++k)
      for (size_t j = 0; j < cur.p[k].size(); ++j) {
        sig[k].push_back(cur.held[k][j] ? 0.0 : std::sqrt(std::max(0.0, C(at, at))));
        if (!cur.held[k][j]) ++at;
      }
  }
  for (auto& ef : rep.effects)
    for (size_t k = 0; k < cur.ext.size(); ++k) {
      if (ef.name != Name(cur.ext[k].effect)) continue;
      const auto names = cur.ext[k].ParameterNames();
      for (size_t j = 0; j < names.size(); ++j) {
        if (cur.held[k][j]) continue;
        ef.parameters.push_back({names[j], cur.p[k][j]});
        ef.sigma.push_back({names[j], sig[k][j]});
      }
    }
  // A clock_offset later extended to clock_drift is reported once, as clock_drift.
  const bool drift = cur.Clock() && cur.Clock()->effect == Effect::kClockDrift;
  if (drift)
    rep.effects.erase(std::remove_if(rep.effects.begin(), rep.effects.end(),
                                     [](const AuditEffect& e) { return e.name == "clock_offset"; }),
                      rep.effects.end());
  return sig;
}

}  // namespace

InclinometerAuditResult AuditInclinometer(const Inclinometer& incl, const std::vector<OrientationReference>& reference,
                                          const std::vector<InclinometerReadingSample>& readings,
                                          const InclinometerAuditOptions& o,
                                          const std::vector<OrientationSample>& motion) {
  std::string why;
  if (!o.IsValid(&why)) Throw("inclinometer audit options: ", why);
  if (!incl.IsValid(&why)) Throw(why);
  const auto say = [&](const std::string& s) {
    if (o.progress) o.progress(s);
  };
  InclinometerAuditResult res;
  AuditReport& rep = res.report;
  rep.mode = "fusion";
  rep.rms_unit = "rad";
  for (size_t i = 1; i < motion.size(); ++i)
    if (!(motion[i].time_s > motion[i - 1].time_s))
      Throw("audit of the inclinometer: the motion record's times must increase (sample ", i + 1, ")");
  const Auditor a(incl, reference, readings, o, motion.size() >= 2 ? motion : std::vector<OrientationSample>{});
  const long N = a.NumReadings();
  if (static_cast<long>(a.NumGroups()) < 4L * o.folds)
    Throw("audit of the inclinometer: only ", a.NumGroups(), " pairs of reference frames with inclinometer readings "
          "between them (within its range, on the same clock); expected at least ", 4 * o.folds,
          " (are the logs on the same clock?)");
  const double alpha_tests = o.false_alarm / 2, alpha_effects = o.false_alarm / 2;
  const std::string& where = o.name;

  // 1. The nominal model and its residual tests.
  Model cur;
  const auto ev0 = a.Evaluate(cur, -1, false);
  rep.nominal_n = 2 * N;
  rep.nominal_chi2_per_dof = ev0.chi2 / (2.0 * N);
  res.noise_scale_nominal = std::sqrt(rep.nominal_chi2_per_dof);
  TestNominalResiduals(a, incl, cur, ev0, N, alpha_tests, where, &rep);

  // 2. Greedy forward selection (audit/model_selection.h).
  const double ln_n = std::log(2.0 * N);
  SelectionRule rule;
  rule.alpha = alpha_effects;
  rule.ln_n = ln_n;
  double cur_ll = a.LogLikAll(cur), cur_ll_cv = 0, cur_rms_cv = 0;
  bool cv_done = false;
  for (int step = 0; step < o.max_effects; ++step) {
    struct Tried {
      Model m;
      std::string label;
      Effect effect = Effect::kInclinometerBias;
      double lr = 0, ll_cv = 0, rms_cv = 0;
      int k = 0;
    };
    std::vector<Tried> tried;
    int kc = -1;
    const Extension* clock = cur.Clock(&kc);
    const auto has = [&](Effect e) {
      for (const auto& x : cur.ext)
        if (x.effect == e) return true;
      return false;
    };
    std::vector<Effect> effects;
    for (Effect e : {Effect::kInclinometerBias, Effect::kInclinometerMisalignment, Effect::kClockOffset,
                     Effect::kClockDrift})
      // clock_drift extends a named clock_offset by its rate (an offset first: a drift alone
      // would tie with it whenever the offset dominates).
      if (!has(e) && !((e == Effect::kClockOffset) && clock) && !(e == Effect::kClockDrift && !clock))
        effects.push_back(e);
    for (Effect e : effects) {
      Tried t;
      t.m = cur;
      t.effect = e;
      Extension x{e, -1, 0};
      if (e == Effect::kClockDrift && clock) {
        // A named clock_offset extended by its rate.
        const double p0 = cur.p[kc][0];
        t.m.ext[kc] = x;
        t.m.p[kc] = {p0, 0.0};
        t.m.held[kc] = {false, false};
        std::swap(t.m.ext[kc], t.m.ext.back());
        std::swap(t.m.p[kc], t.m.p.back());
        std::swap(t.m.held[kc], t.m.held.back());
        t.m.held.back()[0] = true;  // only the rate is tested for identifiability
        t.k = HoldUnidentifiable(a, &t.m);
        t.m.held.back()[0] = false;
      } else {
        t.m.ext.push_back(x);
        t.m.p.push_back(x.InitialParameters());
        t.m.held.push_back(std::vector<bool>(x.NumParameters(), false));
        t.k = HoldUnidentifiable(a, &t.m);
      }
      t.label = std::string(Name(e)) + " at " + where;
      if (t.k == 0) {
        rep.notes.push_back(t.label + ": not identifiable from these data");
        continue;
      }
      say("step " + std::to_string(step + 1) + ": fitting " + t.label);
      t.m = a.Fit(t.m, -1);
      t.lr = 2.0 * (a.LogLikAll(t.m) - cur_ll);
      rep.nested.Record(t.lr, cur_ll);
      tried.push_back(t);
    }
    std::vector<SelectionCandidate> sel(tried.size());
    for (size_t i = 0; i < tried.size(); ++i) {
      sel[i].k = tried[i].k;
      sel[i].lr = tried[i].lr;
    }
    const StepDecision dec = DecideStep(sel, static_cast<int>(sel.size()), rule, [&](int i) {
      if (!cv_done) {
        a.CrossValidate(cur, &cur_ll_cv, &cur_rms_cv);
        cv_done = true;
      }
      say("step " + std::to_string(step + 1) + ": cross-validating " + tried[i].label);
      a.CrossValidate(tried[i].m, &tried[i].ll_cv, &tried[i].rms_cv);
      return tried[i].ll_cv - cur_ll_cv;
    });
    for (size_t i = 0; i < tried.size(); ++i) {
      char b[240];
      std::snprintf(b, sizeof b, "step %d: %s: likelihood ratio %.1f (k %d, p %.3g), BIC gain %.1f", step + 1,
                    tried[i].label.c_str(), tried[i].lr, tried[i].k, sel[i].p_value, sel[i].bic_gain);
      say(b);
    }
    if (dec.outcome == StepOutcome::kNothingPasses) break;
    if (dec.outcome == StepOutcome::kNoHeldoutGain) {
      rep.notes.push_back(tried[dec.best].label +
                          " passed the likelihood-ratio test on all data but did not gain held-out log-likelihood: "
                          "not named");
      break;
    }
    if (dec.outcome == StepOutcome::kUndecided) {
      std::vector<std::string> g;
      for (int i : dec.group) g.push_back(tried[i].label);
      rep.undecided.push_back(g);
      break;  // the sensor's one residual: nothing further is searched
    }
    Tried& best = tried[dec.best];
    AuditEffect ef;
    ef.name = Name(best.effect);
    ef.where = where;
    ef.heldout_rms_before = cur_rms_cv;
    ef.heldout_rms_after = best.rms_cv;
    ef.heldout_loglik_gain = best.ll_cv - cur_ll_cv;
    ef.bic_gain = sel[dec.best].bic_gain;
    rep.effects.push_back(ef);
    cur = best.m;
    cur_ll = a.LogLikAll(cur);
    cur_ll_cv = best.ll_cv;
    cur_rms_cv = best.rms_cv;
  }

  // 3. Sizes and sigmas of the final model.
  const std::vector<std::vector<double>> sig = SizesOfFinalModel(a, cur, &res);
  res.extensions = cur.ext;
  res.parameters = cur.p;
  res.sigmas = sig;
  bool failed = false;
  for (const auto& t : rep.tests) failed |= t.failed;
  rep.clean = !failed && rep.effects.empty() && rep.undecided.empty();
  if (failed && rep.effects.empty())
    rep.notes.push_back(where + ": the nominal model fails a residual test but no effect of the catalog earns its place");
  {
    char b[200];
    std::snprintf(b, sizeof b, "%s: noise scale on the setup's sigma %.3f (nominal model), %.3f (extended)",
                  where.c_str(), res.noise_scale_nominal, res.noise_scale);
    rep.notes.push_back(b);
  }
  const Model nominal;
  for (size_t gi = 0; gi < a.NumGroups(); ++gi) {
    const Group& g = a.Groups()[gi];
    const Eigen::VectorXd r0 = a.Residual(nominal, g, nullptr), r1 = a.Residual(cur, g, nullptr);
    for (size_t i = 0; i < g.readings.size(); ++i) {
      InclinometerAuditResult::Row row;
      row.time_s = a.Reading(g.readings[i]).time_s;
      row.tilt = incl.Tilt(a.OrientationAt(g, row.time_s));
      row.nominal = r0.segment<2>(2 * i);
      row.extended = r1.segment<2>(2 * i);
      res.rows.push_back(row);
    }
  }
  return res;
}

void WriteInclinometerAuditFiles(const InclinometerAuditResult& r, const std::filesystem::path& dir,
                                 const std::string& prefix) {
  constexpr double kDeg = 180.0 / std::numbers::pi;
  WriteFileAtomically(dir / (prefix + "residuals.csv"), [&](std::ostream& os) {
    os << "time_s,tilt_x_deg,tilt_y_deg,nominal_rx_deg,nominal_ry_deg,extended_rx_deg,extended_ry_deg\n";
    char b[256];
    for (const auto& row : r.rows) {
      std::snprintf(b, sizeof b, "%.9g,%.6f,%.6f,%.7f,%.7f,%.7f,%.7f\n", row.time_s, row.tilt[0] * kDeg,
                    row.tilt[1] * kDeg, row.nominal[0] * kDeg, row.nominal[1] * kDeg, row.extended[0] * kDeg,
                    row.extended[1] * kDeg);
      os << b;
    }
  });
  std::filesystem::create_directories(dir / "plots");
  for (int by_tilt = 0; by_tilt < 2; ++by_tilt) {
    Plot p;
    p.title = "inclinometer residuals (predicted - read)" + std::string(by_tilt ? " against tilt" : " against time");
    p.x_label = by_tilt ? "tilt of the axis (deg)" : "time (s)";
    p.y_label = "deg";
    const char* colors[4] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"};
    for (int ext = 0; ext < 2; ++ext)
      for (int axis = 0; axis < 2; ++axis) {
        PlotSeries s;
        s.label = std::string(ext ? "extended" : "nominal") + (axis ? " y" : " x");
        s.color = colors[2 * ext + axis];
        s.points = true;
        for (const auto& row : r.rows) {
          s.x.push_back(by_tilt ? row.tilt[axis] * kDeg : row.time_s);
          s.y.push_back((ext ? row.extended : row.nominal)[axis] * kDeg);
        }
        p.series.push_back(s);
      }
    p.WriteSvg(dir / "plots" / (prefix + (by_tilt ? "residuals_vs_tilt.svg" : "residuals_vs_time.svg")));
  }
}

}  // namespace mcms
