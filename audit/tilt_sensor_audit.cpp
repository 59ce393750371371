#include "audit/tilt_sensor_audit.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include <nlohmann/json.hpp>

#include "audit/model_selection.h"
#include "core/error.h"
#include "core/format.h"
#include "core/io.h"
#include "core/statistics.h"
#include "model/urdf.h"

namespace mcms {

bool TiltSensorAuditOptions::IsValid(std::string* why) const {
  const auto fail = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (!(false_alarm > 0 && false_alarm < 0.5)) return fail("false_alarm must be in (0, 0.5)");
  if (folds < 2) return fail("folds must be at least 2");
  if (max_effects < 0) return fail("max_effects must be >= 0");
  return true;
}

namespace {

using Vec2d = Eigen::Vector2d;
using Mat2d = Eigen::Matrix2d;

struct Row {
  Mat3 R_world_base = Mat3::Identity();  // from the lower sensor's up
  Mat3 R_base_link = Mat3::Identity();   // the upper sensor's link, nominal
  Vec3 moment = Vec3::Zero();            // carried by the upper sensor's frame, base frame (N m)
  double length = 0.0;                   // from the lower frame to the upper (m)
  double travel_left = 0.0;              // the bending joint's travel to its upper limit (m; prismatic)
  Vec2d z = Vec2d::Zero();               // measured tilts of the upper sensor (rad)
  double time_s = 0.0;
};

// Tilts (rad) of a sensor whose measured specific force is a: asin of its up's x and y.
Vec2d TiltsOf(const Vec3& a) {
  const Vec3 u = a.normalized();
  return Vec2d(std::asin(u.x()), std::asin(u.y()));
}

struct Model {
  std::vector<Extension> ext;
  std::vector<std::vector<double>> p;
  std::vector<std::vector<bool>> held;  // held at a physical bound (0)
  int NumFree() const {
    int k = 0;
    for (const auto& h : held)
      for (bool x : h) k += !x;
    return k;
  }
};

bool Bounded(Effect e) { return e == Effect::kLinkCompliance || e == Effect::kSegmentPlay; }
// Telescopic play's overlap at full extension is searched in [kOverlapLo, kOverlapHi] m.
constexpr double kOverlapLo = 0.01, kOverlapHi = 3.0;
// Acts on the link (named by its joint), not on the sensor.
bool OnLink(Effect e) { return Bounded(e) || e == Effect::kAxisTilt; }

class Auditor {
 public:
  Auditor(std::vector<Row> rows, Mat3 R_link_sensor) : rows_(std::move(rows)), R_link_sensor_(R_link_sensor) {}
  int N() const { return static_cast<int>(rows_.size()); }
  const Row& row(int i) const { return rows_[i]; }

  Vec2d Residual(const Model& m, int i) const {
    const Row& r = rows_[i];
    Vec3 beta = Vec3::Zero();
    const double* bias = nullptr;
    Vec3 mis = Vec3::Zero();
    bool misaligned = false;
    for (size_t k = 0; k < m.ext.size(); ++k) {
      const Extension& e = m.ext[k];
      if (e.effect == Effect::kInclinometerBias) {
        bias = m.p[k].data();
      } else if (e.effect == Effect::kInclinometerMisalignment) {
        // Its turn about the sensor's vertical, in the link's frame (variant 1).
        mis = e.variant == 1 ? Vec3(R_link_sensor_.col(2) * m.p[k][0]) : Vec3(m.p[k][0], m.p[k][1], m.p[k][2]);
        misaligned = true;
      } else {
        beta += LinkBendingT<double>(e, m.p[k].data(), r.moment, r.length, r.R_base_link, r.travel_left);
      }
    }
    const Mat3 R = r.R_world_base * ExpSO3(beta) * r.R_base_link;
    return InclinometerReadingOfT<double>(R, R_link_sensor_, misaligned ? mis.data() : nullptr, bias) - r.z;
  }

  // d residual(i) / d parameter, for the parameters idx (block, index), by central
  // differences (a compliance's step scaled to its size: rad per N m^2 times N m^2).
  Eigen::Matrix<double, 2, Eigen::Dynamic> Jacobian(const Model& m, int i,
                                                    const std::vector<std::pair<int, int>>& idx) const {
    Eigen::Matrix<double, 2, Eigen::Dynamic> J(2, idx.size());
    for (size_t c = 0; c < idx.size(); ++c) {
      Model mp = m;
      double& v = mp.p[idx[c].first][idx[c].second];
      const double h =
          1e-7 * std::max(1.0, std::abs(v)) * (m.ext[idx[c].first].effect == Effect::kLinkCompliance ? 1e-3 : 1.0);
      v += h;
      const Vec2d rp = Residual(mp, i);
      v -= 2 * h;
      J.col(c) = (rp - Residual(mp, i)) / (2 * h);
    }
    return J;
  }

  // The model's fit. Telescopic play's overlap (segment_play variant 1's p2, which enters
  // as 1 / (p2 + travel)^2) is profiled: the rest fitted by FitGaussNewton at overlaps on a
  // log grid over [kOverlapLo, kOverlapHi] m, then golden section around the best; an
  // overlap that ends at the grid's edge is held there (at its bound: the data do not place
  // it). The others' Gauss-Newton alone would run it to 0 or past it.
  Model Fit(Model m, const std::vector<char>& mask, const Mat2d* fixed, Mat2d* S_out) const {
    int kp = -1;
    for (size_t k = 0; k < m.ext.size(); ++k)
      if (m.ext[k].effect == Effect::kSegmentPlay && m.ext[k].variant == 1 && !m.held[k][2]) kp = static_cast<int>(k);
    if (kp < 0) return FitGaussNewton(std::move(m), mask, fixed, S_out);
    struct Trial {
      Model m;
      Mat2d S;
      double ll = -std::numeric_limits<double>::infinity();
    };
    const auto at = [&](double overlap) {
      Trial t;
      t.m = m;
      t.m.p[kp][2] = overlap;
      t.m.held[kp][2] = true;
      t.m = FitGaussNewton(std::move(t.m), mask, fixed, &t.S);
      t.ll = LogLik(t.m, t.S, mask, nullptr);
      return t;
    };
    const double lo = std::log(kOverlapLo), hi = std::log(kOverlapHi);
    constexpr int kGrid = 12;
    std::vector<Trial> grid;
    int best = 0;
    for (int g = 0; g <= kGrid; ++g) {
      grid.push_back(at(std::exp(lo + (hi - lo) * g / kGrid)));
      if (grid.back().ll > grid[best].ll) best = g;
    }
    Trial top = grid[best];
    if (best > 0 && best < kGrid) {
      double a = lo + (hi - lo) * (best - 1) / kGrid, b = lo + (hi - lo) * (best + 1) / kGrid;
      const double r = (std::sqrt(5.0) - 1) / 2;
      double c = b - r * (b - a), d = a + r * (b - a);
      Trial tc = at(std::exp(c)), td = at(std::exp(d));
      for (int it = 0; it < 16; ++it) {
        if (tc.ll >= td.ll) {
          b = d, d = c, td = std::move(tc);
          c = b - r * (b - a);
          tc = at(std::exp(c));
        } else {
          a = c, c = d, tc = std::move(td);
          d = a + r * (b - a);
          td = at(std::exp(d));
        }
      }
      for (Trial* t : {&tc, &td})
        if (t->ll > top.ll) top = *t;
    }
    // Where it started, when it is better (a model never fits worse than its start).
    const double start_overlap = m.p[kp][2];
    if (start_overlap >= kOverlapLo && start_overlap <= kOverlapHi) {
      Trial here = at(start_overlap);
      if (here.ll > top.ll) top = std::move(here);
    }
    const double o = top.m.p[kp][2];
    top.m.held[kp][2] = !(o > kOverlapLo * 1.0001 && o < kOverlapHi * 0.9999);
    if (S_out) *S_out = top.S;
    return top.m;
  }

  // Gauss-Newton with the noise covariance profiled, on the rows with mask[i] (all when
  // empty); S fixed when `fixed` is given. Bounded parameters that end below 0 are held at 0.
  Model FitGaussNewton(Model m, const std::vector<char>& mask, const Mat2d* fixed, Mat2d* S_out) const {
    const Model start = m;
    for (int pass = 0; pass < 3; ++pass) {
      Mat2d S = fixed ? *fixed : Covariance(m, mask);
      for (int it = 0; it < 30; ++it) {
        const Mat2d W = S.inverse();
        std::vector<std::pair<int, int>> idx;
        for (size_t k = 0; k < m.p.size(); ++k)
          for (size_t j = 0; j < m.p[k].size(); ++j)
            if (!m.held[k][j]) idx.push_back({static_cast<int>(k), static_cast<int>(j)});
        if (idx.empty()) break;
        const int P = static_cast<int>(idx.size());
        Eigen::MatrixXd H = Eigen::MatrixXd::Zero(P, P);
        Eigen::VectorXd g = Eigen::VectorXd::Zero(P);
        for (int i = 0; i < N(); ++i) {
          if (!mask.empty() && !mask[i]) continue;
          const Vec2d r = Residual(m, i);
          const Eigen::Matrix<double, 2, Eigen::Dynamic> J = Jacobian(m, i, idx);
          H += J.transpose() * W * J;
          g += J.transpose() * W * r;
        }
        const Eigen::VectorXd d = -H.completeOrthogonalDecomposition().solve(g);
        double rel = 0;
        for (int c = 0; c < P; ++c) {
          m.p[idx[c].first][idx[c].second] += d[c];
          rel = std::max(rel, std::abs(d[c]) * std::sqrt(std::max(H(c, c), 0.0)));
        }
        if (!fixed) S = Covariance(m, mask);
        if (rel < 1e-10) break;
      }
      bool changed = false;
      for (size_t k = 0; k < m.p.size(); ++k)
        for (size_t j = 0; j < m.p[k].size(); ++j)
          if (Bounded(m.ext[k].effect) && !m.held[k][j] && m.p[k][j] < 0)
            m.p[k][j] = 0, m.held[k][j] = true, changed = true;
      if (!changed) break;
    }
    // A model with more free parameters never fits worse than where it started (issue 51).
    const Mat2d S_end = fixed ? *fixed : Covariance(m, mask), S_start = fixed ? *fixed : Covariance(start, mask);
    if (!(LogLik(m, S_end, mask, nullptr) >= LogLik(start, S_start, mask, nullptr))) {
      if (S_out) *S_out = S_start;
      return start;
    }
    if (S_out) *S_out = S_end;
    return m;
  }

  Mat2d Covariance(const Model& m, const std::vector<char>& mask) const {
    Mat2d S = Mat2d::Zero();
    int n = 0;
    for (int i = 0; i < N(); ++i)
      if (mask.empty() || mask[i]) {
        const Vec2d r = Residual(m, i);
        S += r * r.transpose();
        ++n;
      }
    S /= std::max(n, 1);
    return S + Mat2d::Identity() * 1e-24;
  }

  // Per-row log-likelihood under N(0, S) of the rows with mask (others 0); their sum.
  double LogLik(const Model& m, const Mat2d& S, const std::vector<char>& mask, std::vector<double>* per_row) const {
    const Mat2d W = S.inverse();
    const double c = -0.5 * std::log(S.determinant()) - std::log(2 * std::numbers::pi);
    double sum = 0;
    if (per_row) per_row->assign(N(), 0.0);
    for (int i = 0; i < N(); ++i) {
      if (!mask.empty() && !mask[i]) continue;
      const Vec2d r = Residual(m, i);
      const double l = c - 0.5 * r.dot(W * r);
      sum += l;
      if (per_row) (*per_row)[i] = l;
    }
    return sum;
  }

  // Held-out log-likelihood of a model (rows in contiguous blocks), each fold's fit on the
  // other blocks from `m`, every fold scored under the metric S; per row into *per_row.
  double HeldOut(const Model& m, int folds, const Mat2d& metric, std::vector<double>* per_row) const {
    double sum = 0;
    per_row->assign(N(), 0.0);
    for (int f = 0; f < folds; ++f) {
      std::vector<char> train(N()), test(N());
      for (int i = 0; i < N(); ++i) (TimeBlockFold(i, N(), folds) == f ? test : train)[i] = 1;
      const Model mf = m.NumFree() > 0 ? Fit(m, train, &metric, nullptr) : m;
      std::vector<double> pr;
      sum += LogLik(mf, metric, test, &pr);
      for (int i = 0; i < N(); ++i)
        if (test[i]) (*per_row)[i] = pr[i];
    }
    return sum;
  }

  // Sigmas of the free parameters at m (the inverse of the Fisher information under S).
  std::vector<std::vector<double>> Sigmas(const Model& m, const Mat2d& S) const {
    std::vector<std::vector<double>> sig(m.p.size());
    std::vector<std::pair<int, int>> idx;
    for (size_t k = 0; k < m.p.size(); ++k) {
      sig[k].assign(m.p[k].size(), 0.0);
      for (size_t j = 0; j < m.p[k].size(); ++j)
        if (!m.held[k][j]) idx.push_back({static_cast<int>(k), static_cast<int>(j)});
    }
    if (idx.empty()) return sig;
    const int P = static_cast<int>(idx.size());
    const Mat2d W = S.inverse();
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(P, P);
    for (int i = 0; i < N(); ++i) {
      const Eigen::Matrix<double, 2, Eigen::Dynamic> J = Jacobian(m, i, idx);
      H += J.transpose() * W * J;
    }
    const Eigen::MatrixXd C = H.completeOrthogonalDecomposition().pseudoInverse();
    for (int c = 0; c < P; ++c) sig[idx[c].first][idx[c].second] = std::sqrt(std::max(C(c, c), 0.0));
    return sig;
  }

 private:
  std::vector<Row> rows_;
  Mat3 R_link_sensor_;
};

// Residual tests of a model's whitened residuals at a family-wise rate alpha: lag-1
// autocorrelation in row order and trends against the carried moment, the bending length
// and time, per axis. Returns every test (failed marked).
std::vector<AuditTest> ResidualTests(const Auditor& a, const Model& m, const Mat2d& S, double alpha,
                                     const std::string& where) {
  const Eigen::LLT<Mat2d> llt(S);
  const Mat2d L = llt.matrixL();
  std::vector<double> w[2], mx, my, len, t;
  for (int i = 0; i < a.N(); ++i) {
    const Vec2d v = L.triangularView<Eigen::Lower>().solve(a.Residual(m, i));
    w[0].push_back(v[0]), w[1].push_back(v[1]);
    mx.push_back(a.row(i).moment.x()), my.push_back(a.row(i).moment.y());
    len.push_back(a.row(i).length), t.push_back(a.row(i).time_s);
  }
  std::vector<AuditTest> tests;
  const char* ax[2] = {"x", "y"};
  for (int k = 0; k < 2; ++k) {
    tests.push_back(AutocorrelationTest(where + ": autocorrelation in row order (" + ax[k] + ")", w[k]));
    for (const auto& [name, x] : {std::pair<const char*, const std::vector<double>*>{"carried moment x", &mx},
                                  {"carried moment y", &my},
                                  {"bending length", &len},
                                  {"time", &t}})
      if (auto tt = TrendTest(where + ": trend vs " + name + " (" + ax[k] + ")", *x, w[k])) tests.push_back(*tt);
  }
  const double per = alpha / tests.size();
  for (auto& x : tests) x.failed = x.p_value < per;
  std::stable_sort(tests.begin(), tests.end(), [](const AuditTest& x, const AuditTest& y) { return x.p_value < y.p_value; });
  return tests;
}

double TiltRms(const Auditor& a, const Model& m) {
  double s = 0;
  for (int i = 0; i < a.N(); ++i) s += a.Residual(m, i).squaredNorm();
  return std::sqrt(s / std::max(1, 2 * a.N()));
}

TiltSensorAuditResult AuditOne(const RobotModel& robot, const RobotLog& log, const LinkMount& ref,
                               const LinkMount& sensor, int ref_k, int sensor_k, const TiltSensorAuditOptions& o) {
  TiltSensorAuditResult res;
  res.sensor = sensor.link;
  res.reference = ref.link;
  res.frame = sensor.frame;
  res.reference_frame = ref.frame;
  res.bending_joint = sensor.frame - 1;
  AuditReport& rep = res.report;
  rep.mode = "tilt sensor";
  rep.rms_unit = "rad";
  const std::string where = sensor.link;
  std::vector<Row> rows;
  const double t0 = log.rows.front().time_s;
  // Telescopic play (segment_play variant 1) where the sensor's link rides a prismatic joint
  // with an upper limit: its travel left is the segments' overlap less what stays at full
  // extension.
  const Joint* bending = res.bending_joint >= 0 ? &robot.Joints()[res.bending_joint] : nullptr;
  const bool telescopic = bending && bending->type == JointType::kPrismatic && std::isfinite(bending->upper);
  for (const RobotMeasurement& lr : log.rows) {
    const std::vector<Pose> frames = robot.LinkFrames(lr.q);
    Row r;
    const Vec3 u = (frames[ref.frame].R * ref.R_frame_link * lr.accel[ref_k].second).normalized();
    r.R_world_base = Eigen::Quaterniond::FromTwoVectors(u, Vec3::UnitZ()).toRotationMatrix();
    r.R_base_link = frames[sensor.frame].R;
    r.moment = CarriedMoment(robot, lr.q, sensor.frame, log.has_payload ? lr.payload_kg.value_or(0.0) : 0.0);
    r.length = (frames[sensor.frame].t - frames[ref.frame].t).norm();
    if (telescopic) r.travel_left = std::max(0.0, bending->upper - lr.q[res.bending_joint]);  // q: chain values
    r.z = TiltsOf(lr.accel[sensor_k].second);
    r.time_s = lr.time_s - t0;
    rows.push_back(r);
    res.moment.push_back(Vec2d(r.moment.x(), r.moment.y()));
  }
  const Auditor a(std::move(rows), sensor.R_frame_link);
  const int N = a.N();
  const std::vector<char> all;
  Model cur;
  Mat2d S0 = a.Covariance(cur, all);
  res.noise_nominal = S0;
  for (int i = 0; i < N; ++i) res.nominal_residuals.push_back(a.Residual(cur, i));
  rep.nominal_n = 2L * N;
  rep.nominal_chi2_per_dof = 1.0;  // the noise is estimated (profiled): nothing to test it against
  if (N < 4 * o.folds) {
    rep.notes.push_back(where + ": " + std::to_string(N) + " rows, fewer than " + std::to_string(4 * o.folds) +
                        ": too few to audit");
    res.noise = S0;
    res.residuals = res.nominal_residuals;
    return res;
  }
  const double alpha_tests = o.false_alarm / 2;
  {
    const std::vector<AuditTest> tests = ResidualTests(a, cur, S0, alpha_tests, where);
    for (const auto& t : tests)
      if (t.failed || rep.tests.size() < 3) rep.tests.push_back(t);
  }
  SelectionRule rule;
  rule.alpha = o.false_alarm / 2;
  rule.ln_n = std::log(2.0 * N);
  Mat2d S_cur = S0;
  double cur_ll = a.LogLik(cur, S_cur, all, nullptr);
  std::optional<double> cur_cv;
  std::vector<double> cur_cv_rows;
  std::vector<Extension> catalog = {{Effect::kInclinometerBias, -1, 0},
                                    {Effect::kInclinometerMisalignment, -1, 1},
                                    {Effect::kLinkCompliance, res.bending_joint, 0},
                                    {Effect::kSegmentPlay, res.bending_joint, 0},
                                    {Effect::kAxisTilt, res.bending_joint, 0}};
  if (telescopic) catalog.push_back({Effect::kSegmentPlay, res.bending_joint, 1});
  const auto Label = [&](const Extension& e) {
    return std::string(Name(e.effect)) + (e.effect == Effect::kSegmentPlay && e.variant == 1 ? " (telescopic)" : "") +
           " at " + (OnLink(e.effect) ? e.Where(robot) : where);
  };
  for (int step = 0; step < o.max_effects; ++step) {
    struct Tried {
      Model m;
      Mat2d S;
      double ll = 0, cv = 0;
      std::vector<double> rows_ll, cv_rows;
      Extension e;
      int k = 0;  // its free parameters
    };
    std::vector<Tried> tried;
    for (const Extension& e : catalog) {
      bool has = false;
      for (const auto& x : cur.ext) has |= x.effect == e.effect;
      if (has) continue;
      Tried t;
      t.e = e;
      t.m = cur;
      t.m.ext.push_back(e);
      t.m.p.push_back(e.InitialParameters());
      t.m.held.push_back(std::vector<bool>(e.NumParameters(), false));
      t.m = a.Fit(t.m, all, nullptr, &t.S);
      const std::vector<bool>& held = t.m.held.back();
      const int n_held = static_cast<int>(std::count(held.begin(), held.end(), true));
      // Telescopic play's overlap (its third parameter) held at the short end of its search:
      // the stations' heights do not place it (none near full extension), the play grows
      // as 1 / travel^2 over those seen. It still competes, its two amplitudes fitted at
      // that overlap, the overlap held and not named. At the long end the play hardly
      // changes with the extension: the constant play's part, and not named.
      const bool overlap_held = e.effect == Effect::kSegmentPlay && e.variant == 1 && held[2] && n_held == 1;
      if (overlap_held && t.m.p.back()[2] > kOverlapLo * 1.0001) {
        rep.notes.push_back(Label(e) + ": the overlap the data ask for lies beyond 3 m (a play that hardly grows "
                            "with the extension): held at the end and not named");
        continue;
      }
      if (n_held > 0 && !overlap_held) {
        rep.notes.push_back(Label(e) + ": the data ask for a negative value (a link bending against its load): held "
                            "at 0 and not named");
        continue;
      }
      if (overlap_held) {
        double least_travel = std::numeric_limits<double>::infinity();
        for (int i = 0; i < N; ++i) least_travel = std::min(least_travel, a.row(i).travel_left);
        const std::string note =
            Label(e) + Format(": the stations do not place the overlap left at full extension (its likelihood is "
                              "highest at the end of its 0.01-3 m search; the highest station leaves %.3g m of travel): "
                              "held at %.3g m, the play's amplitudes fitted for it",
                              least_travel, t.m.p.back()[2]);
        if (std::find(rep.notes.begin(), rep.notes.end(), note) == rep.notes.end()) rep.notes.push_back(note);
      }
      t.k = e.NumParameters() - n_held;
      t.ll = a.LogLik(t.m, t.S, all, &t.rows_ll);
      rep.nested.Record(2 * (t.ll - cur_ll), cur_ll);
      tried.push_back(std::move(t));
    }
    if (tried.empty()) break;
    std::vector<SelectionCandidate> sel(tried.size());
    for (size_t i = 0; i < tried.size(); ++i) {
      sel[i].k = tried[i].k;
      sel[i].lr = std::max(0.0, 2 * (tried[i].ll - cur_ll));
      sel[i].row_loglik = tried[i].rows_ll;
    }
    const StepDecision dec = DecideStep(sel, static_cast<int>(sel.size()), rule, [&](int i) {
      if (!cur_cv) cur_cv = a.HeldOut(cur, o.folds, S_cur, &cur_cv_rows);
      tried[i].cv = a.HeldOut(tried[i].m, o.folds, S_cur, &tried[i].cv_rows);
      sel[i].heldout_row_loglik = tried[i].cv_rows;
      return tried[i].cv - *cur_cv;
    });
    if (dec.outcome == StepOutcome::kNothingPasses) break;
    if (dec.outcome == StepOutcome::kNoHeldoutGain) {
      rep.notes.push_back(Label(tried[dec.best].e) +
                          " passed the likelihood-ratio test on all data but did not gain held-out log-likelihood: not "
                          "named");
      break;
    }
    const auto Effect_ = [&](const Extension& e, const Model& after, double heldout_gain, double bic_gain) {
      AuditEffect ef;
      ef.name = Name(e.effect);
      ef.where = OnLink(e.effect) ? e.Where(robot) : where;
      if (e.effect == Effect::kSegmentPlay && e.variant == 1)
        ef.labels = {{"variant", "telescopic: (play_x s_x, play_y s_y) / (overlap_at_full_extension + travel left)^2"}};
      ef.rms_unit = "rad";
      ef.heldout_rms_before = TiltRms(a, cur);
      ef.heldout_rms_after = TiltRms(a, after);
      ef.heldout_loglik_gain = heldout_gain;
      ef.bic_gain = bic_gain;
      return ef;
    };
    if (dec.outcome == StepOutcome::kUndecided) {
      // Two causes that explain the same residual equally well may both be present: fitted
      // together, they are named together when each adds to the other (its likelihood
      // ratio over the other alone passes the selection's test for its parameters), no
      // parameter ends at a bound, and the pair gains held-out log-likelihood over the
      // better one alone. Otherwise the tie is reported.
      bool named = false;
      if (dec.group.size() == 2 && tried[dec.group[0]].e.effect != tried[dec.group[1]].e.effect) {
        const Tried& t0 = tried[dec.group[0]];
        const Tried& t1 = tried[dec.group[1]];
        Model both = t0.m;
        both.ext.push_back(t1.e);
        both.p.push_back(t1.m.p.back());
        both.held.push_back(t1.m.held.back());
        Mat2d S_both;
        both = a.Fit(both, all, nullptr, &S_both);
        bool bound = false;
        for (size_t k = cur.ext.size(); k < both.ext.size(); ++k)
          for (bool h : both.held[k]) bound |= h;
        const double ll = a.LogLik(both, S_both, all, nullptr);
        rep.nested.Record(2 * (ll - t0.ll), t0.ll);
        rep.nested.Record(2 * (ll - t1.ll), t1.ll);
        const bool adds0 = 2 * (ll - t1.ll) > ChiSquareThreshold(t0.k, rule.alpha);
        const bool adds1 = 2 * (ll - t0.ll) > ChiSquareThreshold(t1.k, rule.alpha);
        if (!bound && adds0 && adds1) {
          std::vector<double> rows_cv;
          const double cv = a.HeldOut(both, o.folds, S_cur, &rows_cv);
          const double best_single = std::max(t0.cv, t1.cv);
          if (cv > best_single) {
            const double k = t0.k + t1.k;
            const double bic = 2 * (ll - cur_ll) - k * rule.ln_n;
            rep.effects.push_back(Effect_(t0.e, both, cv - *cur_cv, bic));
            rep.effects.push_back(Effect_(t1.e, both, cv - *cur_cv, bic));
            rep.notes.push_back(Label(t0.e) + " and " + Label(t1.e) +
                                " explain the same residual equally well alone; fitted together each adds to the "
                                "other and the pair predicts held-out rows better: both named");
            cur = std::move(both);
            S_cur = S_both;
            cur_ll = ll;
            cur_cv.reset();
            named = true;
          }
        }
      }
      if (named) continue;
      std::vector<std::string> g;
      for (int i : dec.group) g.push_back(Label(tried[i].e));
      rep.undecided.push_back(g);
      break;
    }
    Tried& best = tried[dec.best];
    rep.effects.push_back(Effect_(best.e, best.m, best.cv - *cur_cv, sel[dec.best].bic_gain));
    cur = best.m;
    S_cur = best.S;
    cur_ll = best.ll;
    // The next step's metric is this model's noise: its held-out baseline is recomputed.
    cur_cv.reset();
  }
  // Sizes and sigmas; the final residuals' tests.
  const auto sig = a.Sigmas(cur, S_cur);
  res.extensions = cur.ext;
  res.parameters = cur.p;
  res.sigmas = sig;
  for (size_t k = 0; k < rep.effects.size() && k < cur.ext.size(); ++k) {
    AuditEffect& ef = rep.effects[k];
    const auto names = cur.ext[k].ParameterNames();
    for (size_t j = 0; j < names.size(); ++j) {
      if (cur.held[k][j]) {  // a telescopic play's overlap the stations do not place
        ef.labels.push_back({names[j], Format("%.4g (held at the end of its search: the data do not place it)",
                                              cur.p[k][j])});
        continue;
      }
      ef.parameters.push_back({names[j], cur.p[k][j]});
      ef.sigma.push_back({names[j], sig[k][j]});
      const bool telescopic_play = cur.ext[k].effect == Effect::kSegmentPlay && cur.ext[k].variant == 1;
      ef.units.push_back(cur.ext[k].effect == Effect::kLinkCompliance || cur.ext[k].effect == Effect::kAxisTilt ||
                                 telescopic_play
                             ? ""
                             : "rad");
    }
  }
  res.noise = S_cur;
  for (int i = 0; i < N; ++i) res.residuals.push_back(a.Residual(cur, i));
  const std::vector<AuditTest> after = ResidualTests(a, cur, S_cur, alpha_tests, where);
  rep.tests_after_run = static_cast<int>(after.size());
  for (const auto& t : after)
    if (t.failed) rep.tests_after.push_back(t);
  bool failed = false;
  for (const auto& t : rep.tests) failed |= t.failed;
  rep.clean = !failed && rep.effects.empty() && rep.undecided.empty();
  char b[300];
  std::snprintf(b, sizeof b,
                "%s against %s: %d rows; tilt residual RMS %.4f mrad nominal, %.4f mrad final; noise sigma x y "
                "%.4f %.4f mrad (fitted)",
                where.c_str(), ref.link.c_str(), N, TiltRms(a, Model{}) * 1e3, TiltRms(a, cur) * 1e3,
                std::sqrt(S_cur(0, 0)) * 1e3, std::sqrt(S_cur(1, 1)) * 1e3);
  rep.notes.insert(rep.notes.begin(), b);
  return res;
}

}  // namespace

std::vector<TiltSensorAuditResult> AuditTiltSensors(const RobotModel& robot, const RobotLog& log,
                                                    const TiltSensorAuditOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) Throw("tilt sensor audit options: ", why);
  if (!robot.Urdf() || log.rows.empty() || log.rows.front().accel.size() < 2) return {};
  std::vector<LinkMount> mounts;
  for (const auto& [link, a] : log.rows.front().accel) mounts.push_back(MountOnChain(robot, link));
  for (const RobotMeasurement& r : log.rows) {
    if (r.accel.size() != mounts.size()) return {};
    for (size_t k = 0; k < mounts.size(); ++k)
      if (r.accel[k].first != mounts[k].link) return {};
  }
  int ref = 0;
  for (size_t k = 1; k < mounts.size(); ++k)
    if (mounts[k].frame < mounts[ref].frame) ref = static_cast<int>(k);
  std::vector<TiltSensorAuditResult> out;
  for (size_t k = 0; k < mounts.size(); ++k) {
    if (mounts[k].frame <= mounts[ref].frame) continue;
    if (!robot.HasMasses())
      Throw(log.source.string(), ": the tilt sensor ", mounts[k].link, " is audited against the moment its link carries, "
            "but robot '", robot.Name(), "' gives no link masses (URDF <inertial><mass>)");
    out.push_back(AuditOne(robot, log, mounts[ref], mounts[k], ref, static_cast<int>(k), o));
  }
  return out;
}

std::string TiltSensorAuditText(const std::vector<TiltSensorAuditResult>& results, const RobotModel&) {
  std::string out;
  for (const TiltSensorAuditResult& r : results) {
    out += "tilt sensor " + r.sensor + " (against " + r.reference + ", the chain between them in the model):\n";
    std::string body = r.report.Text();
    out += body;
    const bool in_band = r.report.tests_after.empty() && r.report.tests_after_run > 0;
    out += in_band ? "  tilt residuals in band: the final model's residuals pass every one of the " +
                         std::to_string(r.report.tests_after_run) + " residual tests\n"
                   : "  tilt residuals not in band: " + std::to_string(r.report.tests_after.size()) + " of " +
                         std::to_string(r.report.tests_after_run) + " residual tests still fail\n";
  }
  return out;
}

nlohmann::json TiltSensorAuditJson(const std::vector<TiltSensorAuditResult>& results) {
  nlohmann::json a = nlohmann::json::array();
  for (const TiltSensorAuditResult& r : results) {
    nlohmann::json j;
    j["sensor"] = r.sensor;
    j["reference"] = r.reference;
    j["report"] = nlohmann::json::parse(r.report.ToJson());
    j["noise_sigma_rad"] = {std::sqrt(r.noise(0, 0)), std::sqrt(r.noise(1, 1))};
    j["noise_sigma_nominal_rad"] = {std::sqrt(r.noise_nominal(0, 0)), std::sqrt(r.noise_nominal(1, 1))};
    j["in_band"] = r.report.tests_after.empty() && r.report.tests_after_run > 0;
    a.push_back(j);
  }
  return a;
}

void WriteTiltSensorResiduals(const std::filesystem::path& path, const std::vector<TiltSensorAuditResult>& results) {
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "row,sensor,nominal_x_mrad,nominal_y_mrad,final_x_mrad,final_y_mrad,moment_x_Nm,moment_y_Nm\n";
    char b[320];
    for (const TiltSensorAuditResult& r : results)
      for (size_t i = 0; i < r.residuals.size(); ++i) {
        std::snprintf(b, sizeof b, "%zu,%s,%.6f,%.6f,%.6f,%.6f,%.4f,%.4f\n", i + 1, r.sensor.c_str(),
                      r.nominal_residuals[i][0] * 1e3, r.nominal_residuals[i][1] * 1e3, r.residuals[i][0] * 1e3,
                      r.residuals[i][1] * 1e3, r.moment[i][0], r.moment[i][1]);
        os << b;
      }
  });
}

}  // namespace mcms
