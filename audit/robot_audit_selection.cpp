#include "audit/robot_audit_selection.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <numeric>
#include <optional>

#include "audit/model_selection.h"
#include "model/identifiability.h"
#include "core/error.h"
#include "core/random.h"

namespace mcms::robot_audit {

namespace {

constexpr double kMaxJointScale = 5e-3;
// Physical bounds of the flexible and thermal terms (issue 51: a 0.56 % "warm-up" and a
// 1.66 rad error motion were fitted where the catalog lacked the cause): no robot's links
// grow by more than 0.1 % (aluminium warmed by 43 K) or by more than 1e-4 per kelvin, and no
// rotary axis wobbles by more than 10 mrad or 5 mm (ISO 230-7 error motions of robot joints
// are tenths of a millirad and of a millimetre).
constexpr double kMaxThermalGrowth = 1e-3, kMaxGrowthPerKelvin = 1e-4;
constexpr double kMaxErrorMotionRad = 0.01, kMaxErrorMotionM = 0.005;

// A single geometric kind is offered when asked for by name, or with the whole geometry.
bool GeometricKindWanted(const RobotAuditOptions& o, Effect e) {
  return Wanted(o, e) || Wanted(o, Effect::kGeometry);
}

// A fit that ended below the model it extends: a failed solve, not evidence (issue 51).
std::string FailedSolveNote(const std::string& key, double lr) {
  char b[300];
  std::snprintf(b, sizeof b,
                "%s: its fit ended below the model it extends (likelihood ratio %.3g): a failed solve, not "
                "evidence; not named",
                key.c_str(), lr);
  return b;
}

}  // namespace

bool Wanted(const RobotAuditOptions& o, Effect e) {
  return o.only.empty() || std::find(o.only.begin(), o.only.end(), Name(e)) != o.only.end();
}
bool GeometryWanted(const RobotAuditOptions& o) {
  for (Effect e : {Effect::kGeometry, Effect::kJointOffset, Effect::kLinkLength, Effect::kLinkTwist})
    if (Wanted(o, e)) return true;
  return false;
}

// The blocks of theta and the candidates that free them: the geometric terms (stage 2)
// and the rest of the catalog (stage 3).
void MakeLayout(Problem* pb, const RobotLog& log, const RobotAuditOptions& o, std::vector<Option>* geometric,
                std::vector<Option>* others, std::vector<std::string>* notes) {
  const RobotModel& robot = *pb->robot;
  const int n = pb->n;
  std::vector<Extension>& B = pb->blocks;
  B.push_back({Effect::kGeometry, -1, robot.NumGeometryParameters()});
  pb->geometry = 0;
  const bool masses = robot.HasMasses();
  bool moves_both_ways = false;
  for (int j = 0; j < n && !moves_both_ways; ++j) {
    bool up = false, down = false;
    for (const RowData& r : pb->rows) {
      up |= r.c.move_direction[j] > 0;
      down |= r.c.move_direction[j] < 0;
    }
    moves_both_ways = up && down;
  }
  for (int j = 0; j < n; ++j) {
    if (robot.Joints()[j].type == JointType::kRevolute && Wanted(o, Effect::kErrorMotion))
      B.push_back({Effect::kErrorMotion, j, 1});
    if (Wanted(o, Effect::kJointScale)) B.push_back({Effect::kJointScale, j, 0});
    if (Wanted(o, Effect::kGravityCompliance)) B.push_back({Effect::kGravityCompliance, j, masses ? 0 : 2 * n + 1});
    if (Wanted(o, Effect::kBacklash) && moves_both_ways) B.push_back({Effect::kBacklash, j, 0});
  }
  if (Wanted(o, Effect::kBacklash) && !moves_both_ways)
    notes->push_back("backlash not tested: no joint moves both ways in the log");
  if (Wanted(o, Effect::kThermalDrift)) {
    const double span = log.rows.back().time_s - log.rows.front().time_s;
    if (!log.has_time)
      notes->push_back("thermal_drift in time not tested: the log has no time column");
    else if (span > 0)
      B.push_back({Effect::kThermalDrift, -1, 0});
    else
      notes->push_back("thermal_drift in time not tested: the log has no time span");
    if (log.has_temperature) B.push_back({Effect::kThermalDrift, -1, 1});
  }
  bool moving = false;
  for (const auto& r : log.rows) moving |= r.qdot.size() > 0 && r.qdot.norm() > 0;
  if (Wanted(o, Effect::kClockOffset) && moving) B.push_back({Effect::kClockOffset, -1, 0});

  // Parameters: station 0's registration and the tool, the blocks, the other stations'
  // registrations.
  pb->P = pb->NumBase();
  for (const Extension& e : B) {
    pb->offset.push_back(pb->P);
    pb->P += e.NumParameters();
  }
  pb->reg_extra = pb->P;
  pb->P += 6 * (pb->S - 1);
  pb->theta0 = Eigen::VectorXd::Zero(pb->P);
  pb->lower.assign(pb->P, -kInf);
  pb->upper.assign(pb->P, kInf);
  for (size_t k = 0; k < B.size(); ++k) {
    const std::vector<double> p0 = B[k].InitialParameters();
    for (size_t j = 0; j < p0.size(); ++j) pb->theta0[pb->offset[k] + j] = p0[j];
    // Physical bounds: no joint has a negative compliance or mass, nor a negative backlash.
    if (B[k].effect == Effect::kGravityCompliance || B[k].effect == Effect::kBacklash)
      for (int j = 0; j < B[k].NumParameters(); ++j) pb->lower[pb->offset[k] + j] = 0.0;
    // Nor a gear ratio off by more than half a percent (a joint read 1 rad as 0.995 would be
    // broken, not misscaled), nor play of more than 0.1 rad (5.7 deg) or 5 mm.
    if (B[k].effect == Effect::kJointScale) {
      pb->lower[pb->offset[k]] = -kMaxJointScale;
      pb->upper[pb->offset[k]] = kMaxJointScale;
    }
    if (B[k].effect == Effect::kBacklash)
      pb->upper[pb->offset[k]] = robot.Joints()[B[k].index].type == JointType::kRevolute ? 0.1 : 0.005;
    // Nor a compliance that sags a joint by more than kMaxGravityDeflection: each parameter
    // (the compliance, or one lumped mass moment) alone, at its largest lever in the log.
    if (B[k].effect == Effect::kGravityCompliance) {
      const int j = B[k].index;
      const double most = robot.Joints()[j].type == JointType::kRevolute ? kMaxGravityDeflectionRad
                                                                         : kMaxGravityDeflectionM;
      for (int c = 0; c < B[k].NumParameters(); ++c) {
        double lever = 0.0;
        for (const RowData& r : pb->rows)
          lever = std::max(lever, std::abs(B[k].variant == 0 ? (r.c.gravity_torque.size() > j ? r.c.gravity_torque[j] : 0.0)
                                                             : (r.c.gravity_lever.rows() > j ? r.c.gravity_lever(j, c) : 0.0)));
        if (lever > 0) pb->upper[pb->offset[k] + c] = most / lever;
      }
    }
    // A placement off by more than kMaxGeometryErrorRad or kMaxGeometryErrorM is a robot file
    // of another robot, not a calibration (and a fit that goes there has wandered along a
    // direction the poses barely see).
    if (B[k].effect == Effect::kGeometry)
      for (int j = 0; j < B[k].NumParameters(); ++j) {
        const double most = GeometryParameterIsAngle(robot, j) ? kMaxGeometryErrorRad : kMaxGeometryErrorM;
        pb->lower[pb->offset[k] + j] = -most;
        pb->upper[pb->offset[k] + j] = most;
      }
    if (B[k].effect == Effect::kThermalDrift) {
      const double most = B[k].variant == 0 ? kMaxThermalGrowth : kMaxGrowthPerKelvin;
      pb->lower[pb->offset[k]] = -most;
      pb->upper[pb->offset[k]] = most;
    }
    if (B[k].effect == Effect::kErrorMotion)
      for (int j = 0; j < B[k].NumParameters(); ++j) {
        const double most = j % 6 < 3 ? kMaxErrorMotionRad : kMaxErrorMotionM;
        pb->lower[pb->offset[k] + j] = -most;
        pb->upper[pb->offset[k] + j] = most;
      }
    if (B[k].effect == Effect::kThermalDrift && B[k].variant == 0) pb->warmup = pb->offset[k];
  }

  // Geometric candidates: one term each of the geometry block (a DH table's offsets, lengths
  // and twists; a URDF chain's zero offsets, its placements only all at once).
  const int g0 = pb->offset[pb->geometry], s = robot.GeometryParamsPerJoint();
  for (int j = 0; j < n; ++j) {
    const bool rev = robot.Joints()[j].type == JointType::kRevolute;
    const auto Add = [&](Extension e, int term) {
      if (!GeometricKindWanted(o, e.effect)) return;
      geometric->push_back({e.Label(robot), e, {g0 + s * j + term}, 0, true});
    };
    Add({Effect::kJointOffset, j, 0}, robot.OffsetParameter(j));
    if (!robot.HasDhTerms()) continue;  // a URDF chain's placements: `geometry`
    if (rev) Add({Effect::kLinkLength, j, 1}, 1);
    Add({Effect::kLinkLength, j, 0}, 2);
    Add({Effect::kLinkTwist, j, 0}, 3);
  }
  // The rest: a block each, error motion one axis's sine/cosine pair at a time.
  for (size_t k = 1; k < B.size(); ++k) {
    const Extension& e = B[k];
    if (e.effect == Effect::kErrorMotion) {
      // One kind of error motion at a time (ISO 230-7): tilt, angular, radial, axial, each
      // a first-harmonic sine/cosine pair. A radial (or tilt) motion along x and one along
      // y differ only by a part that turns with the joint, which is a DH change: the
      // geometry holds it, so x (rx) stands for both.
      static const std::pair<int, const char*> kKinds[4] = {{0, "tilt"}, {2, "angular"}, {3, "radial"}, {5, "axial"}};
      for (const auto& [a, kind] : kKinds)
        others->push_back({e.Label(robot) + " (" + kind + ")", e, {pb->offset[k] + a, pb->offset[k] + 6 + a}, 2, false});
    } else if (e.effect == Effect::kThermalDrift && e.variant == 0) {
      others->push_back({e.Label(robot) + " (warm-up)", e, {pb->offset[k]}, 0, false});  // the time constant is profiled
    } else {
      std::vector<int> t(e.NumParameters());
      std::iota(t.begin(), t.end(), pb->offset[k]);
      // Lumped masses: the tool point (the payload) first, then the link frames from the
      // flange inward, so that of two points the data cannot tell apart the outer is kept.
      if (e.effect == Effect::kGravityCompliance && e.variant > 0) std::reverse(t.begin(), t.end());
      std::string key = e.Label(robot);
      if (e.effect == Effect::kThermalDrift) key += " (temperature)";
      others->push_back({key, e, t, 0, false});
    }
  }
}

// The registration and the tool of the nominal model by maximum likelihood (Ceres; the
std::string GeometryName(const Problem& pb, int p) {
  return GeometryParameterNames(*pb.robot).at(p - pb.offset[pb.geometry]);
}

Identifiable GeometryIdentifiability(const Problem& pb, const Eigen::MatrixXd& noise, double tol) {
  const int g0 = pb.offset[pb.geometry], ng = pb.robot->NumGeometryParameters();
  std::vector<int> cols;
  std::vector<std::string> names;
  static const char* kBase[6] = {".rx", ".ry", ".rz", ".x", ".y", ".z"};
  static const char* kTool[6] = {"tool.x", "tool.y", "tool.z", "tool.rx", "tool.ry", "tool.rz"};
  // The placements first (they may be anything), then the tool: a tool offset that only
  // moves every station alike (a prism always below a vertical flange) is the one held.
  for (int k = 0; k < 6; ++k) cols.push_back(k), names.push_back(std::string("base") + kBase[k]);
  for (int st = 1; st < pb.S; ++st)
    for (int k = 0; k < 6; ++k)
      cols.push_back(pb.RegOffset(st) + k), names.push_back("base@" + pb.station_names[st] + kBase[k]);
  for (int k = 0; k < pb.ts; ++k) cols.push_back(6 + k), names.push_back(kTool[k]);
  const int nb = static_cast<int>(cols.size());
  for (int k = 0; k < ng; ++k)
    cols.push_back(g0 + k), names.push_back(GeometryName(pb, g0 + k));
  const Eigen::MatrixXd Li = WhiteningOf(noise);
  Eigen::MatrixXd Jw(static_cast<Eigen::Index>(pb.N) * pb.m, cols.size());
  for (size_t c = 0; c < cols.size(); ++c)
    for (int i = 0; i < pb.N; ++i)
      for (int a = 0; a < pb.m; ++a) {
        double v = 0;
        for (int b = 0; b <= a; ++b) v += Li(a, b) * pb.J[b](i, cols[c]);
        Jw(static_cast<Eigen::Index>(i) * pb.m + a, c) = v;
      }
  std::vector<ParameterStatus> params(cols.size());
  // The registrations may be anything; the tool and each geometric parameter no worse
  // determined than a robot's placement could be off (a tool offset the poses fix only to
  // centimetres is held at the robot file's).
  std::vector<double> largest(cols.size(), 0.0);
  for (int k = 0; k < pb.ts; ++k) largest[nb - pb.ts + k] = k < 3 ? kWeakGeometryLengthM : kWeakGeometryAngleRad;
  for (int k = 0; k < ng; ++k) largest[nb + k] = WeakGeometrySigma(*pb.robot, k);
  AnalyzeIdentifiability(Jw, names, tol, &params, largest);
  Identifiable id;
  for (int c = 0; c < nb; ++c)
    if (params[c].fixed) id.held_base.push_back({cols[c], names[c] + ": " + params[c].reason});
  for (int k = 0; k < ng; ++k) {
    const ParameterStatus& p = params[nb + k];
    if (p.fixed)
      id.held.push_back({names[nb + k], p.reason});
    else
      id.params.push_back(g0 + k);
  }
  return id;
}

// ---------------------------------------------------------------------------------
// Greedy selection: screening, full fits, the selection rule

// A candidate's identifiable terms on top of the current model and the chi-square its
// linearised (unconstrained) fit removes, with the unconstrained estimates.
struct Screened {
  int option = -1;
  std::vector<int> terms;
  double gain = 0.0;
  Eigen::VectorXd estimate, sigma;
};

std::vector<Screened> Screen(const Problem& pb, const FitResult& cur, const std::vector<Option>& opts,
                             const std::vector<int>& open, double tol, std::vector<std::string>* not_identifiable) {
  std::vector<int> C;
  for (int oi : open)
    for (int t : opts[oi].terms)
      if (std::find(cur.free.begin(), cur.free.end(), t) == cur.free.end() &&
          std::find(C.begin(), C.end(), t) == C.end())
        C.push_back(t);
  std::vector<Screened> out;
  if (C.empty()) return out;
  const std::vector<int> FC = Union(cur.free, C);
  Eigen::VectorXd th = cur.theta;
  if (pb.warmup >= 0 && std::find(C.begin(), C.end(), pb.warmup) != C.end() && th[pb.warmup] == 0.0)
    th[pb.warmup + 1] = pb.time_span / 3.0;  // a representative warm-up for screening
  const Columns cols(pb, FC, th);
  const RowSet all = AllRows(pb);
  const Eigen::MatrixXd W = cur.noise.inverse();
  const Eigen::MatrixXd H = cols.Normal(all, W);
  const Eigen::VectorXd g = cols.Gradient(all, W, cur.R);
  const int nf = cur.free.size();
  const Eigen::MatrixXd HffInv = InverseScaled(H.topLeftCorner(nf, nf));
  const auto Pos = [&](int param) { return static_cast<int>(std::find(FC.begin(), FC.end(), param) - FC.begin()); };
  for (int oi : open) {
    std::vector<int> pos;
    for (int t : opts[oi].terms)
      if (std::find(cur.free.begin(), cur.free.end(), t) == cur.free.end()) pos.push_back(Pos(t));
    if (pos.empty()) continue;
    const Eigen::MatrixXd Hcf = H(pos, Eigen::seqN(0, nf));
    const Eigen::MatrixXd S = H(pos, pos) - Hcf * HffInv * Hcf.transpose();
    const Eigen::VectorXd h = g(pos) - Hcf * HffInv * g.head(nf);
    // Identifiable terms: greedy, each against the model and the terms kept before it.
    std::vector<int> keep;
    for (size_t t = 0; t < pos.size(); ++t) {
      double d = S(t, t);
      if (!keep.empty()) {
        const Eigen::MatrixXd Skk = S(keep, keep);
        const Eigen::VectorXd skt = S(keep, Eigen::seqN(static_cast<int>(t), 1));
        d -= skt.dot(SolveScaled(Skk, skt));
      }
      const double hn = H(pos[t], pos[t]);
      if (hn > 0 && d > 0 && std::sqrt(d / hn) >= tol) keep.push_back(static_cast<int>(t));
    }
    if (keep.empty()) {
      not_identifiable->push_back(opts[oi].key);
      continue;
    }
    Screened s;
    s.option = oi;
    for (int k : keep) s.terms.push_back(FC[pos[k]]);
    const Eigen::MatrixXd Sk = S(keep, keep);
    const Eigen::MatrixXd Ski = InverseScaled(Sk);
    const Eigen::VectorXd hk = h(keep);
    s.gain = hk.dot(Ski * hk);
    s.estimate = -Ski * hk;
    s.sigma = Ski.diagonal().cwiseMax(0.0).cwiseSqrt();
    out.push_back(s);
  }
  return out;
}


// The full fit of a candidate on top of `cur`.
Tried FitCandidate(const Problem& pb, const FitResult& cur, int option, const std::vector<int>& terms) {
  Tried t;
  t.option = option;
  t.terms = terms;
  t.fit = FitProfiled(pb, Union(cur.free, terms), cur.theta, cur.noise, &t.tau_sigma);
  return t;
}



// The flexible family re-tested after every accepted step (issue 35): an error motion named
// earlier (or just now) is taken out of the model and every physical candidate of the
// catalog not in the model is fitted in its place, on top of everything else now in it.
// Where the best of them passes the step's test on that base and explains the residual as
// well as the error motion did (Vuong's paired z with the BIC correction below the tie
// band, as rule 4 of audit/model_selection.h), it replaces the error motion: a harmonic
// series follows the shape of a joint's deflection under the arm's weight or of its play
// too, and a physical cause is preferred where the data cannot tell them apart (rule 5).
void RetestFlexible(const Problem& pb, const std::vector<Option>& opts, const RobotAuditOptions& o, double alpha,
                    std::set<int>* taken, SelectionResult* res, std::vector<std::string>* notes, NestedFits* nested,
                    const std::function<void(const std::string&)>& say) {
  const double logN = std::log(static_cast<double>(pb.N));
  const SelectionRule rule;
  for (Finding& g : res->findings) {
    if (g.undecided || g.dropped || opts[g.option].tier != 2) continue;
    std::vector<int> free;
    for (int t : res->cur.free)
      if (std::find(g.terms.begin(), g.terms.end(), t) == g.terms.end()) free.push_back(t);
    Eigen::VectorXd th = res->cur.theta;
    for (int t : g.terms) th[t] = pb.theta0[t];
    const FitResult base = FitProfiled(pb, free, th, res->cur.noise);
    std::vector<int> physical;
    for (size_t i = 0; i < opts.size(); ++i)
      if (opts[i].tier == 0 && !opts[i].geometric && !taken->count(static_cast<int>(i)))
        physical.push_back(static_cast<int>(i));
    if (physical.empty()) continue;
    std::vector<std::string> ignored;
    const std::vector<Screened> sc = Screen(pb, base, opts, physical, o.identifiability_tolerance, &ignored);
    const int M = static_cast<int>(sc.size());
    std::optional<Tried> best;
    double best_z = kInf;
    const int k_em = ParamCount(pb, g.terms);
    for (const Screened& s : sc) {
      const int k = ParamCount(pb, s.terms);
      if (s.gain < 0.3 * ChiSquareThreshold(k, alpha / M)) continue;
      Tried t = FitCandidate(pb, base, s.option, s.terms);
      t.lr = 2.0 * (t.fit.loglik - base.loglik);
      t.bic = BicGain(t.lr, k, logN);
      if (!nested->Record(t.lr, base.loglik)) {
        notes->push_back(FailedSolveNote(opts[s.option].key, t.lr));
        continue;
      }
      if (t.lr < ChiSquareThreshold(k, alpha / M) || t.bic <= 0) continue;
      const std::vector<double> a(res->cur.row_ll.data(), res->cur.row_ll.data() + pb.N);
      const std::vector<double> b(t.fit.row_ll.data(), t.fit.row_ll.data() + pb.N);
      // z > 0: the error motion explains the residual better than this cause.
      const double z = PairedZ(a, b, 0.5 * (k_em - k) * logN);
      if (z < best_z) {
        best_z = z;
        best = std::move(t);
      }
    }
    if (!best || !(best_z < rule.tie_z)) continue;
    const std::string was = opts[g.option].key, now = opts[best->option].key;
    char b[400];
    std::snprintf(b, sizeof b,
                  "%s was named, then re-tested with the later effects in: %s explains the same residual (likelihood "
                  "ratio %.1f on the same base, paired z %.2f against the error motion, tie below %.3g) and, being "
                  "a physical cause, is named in its place",
                  was.c_str(), now.c_str(), best->lr, best_z, rule.tie_z);
    say(b);
    notes->push_back(b);
    taken->erase(g.option);
    taken->insert(best->option);
    const HeldOut base_cv = CrossValidate(pb, base, res->cur.noise);
    best->cv = CrossValidate(pb, best->fit, res->cur.noise);
    best->cv_done = true;
    g.option = best->option;
    g.terms = best->terms;
    g.lr = best->lr;
    g.bic = best->bic;
    g.tau_sigma = best->tau_sigma;
    g.base_cv_loglik = base_cv.loglik;
    g.rms_before = base_cv.rms;
    g.ll_gain = best->cv.loglik - base_cv.loglik;
    g.rms_after = best->cv.rms;
    res->cur = best->fit;
    res->cur_cv = CrossValidate(pb, res->cur, res->cur.noise);
    res->cv_known = true;
  }
}

// Greedy forward selection over every candidate, from `start`: single geometric terms,
// the whole identifiable geometry (`geometry_terms`, offered as one candidate while the
// data can hold it), and the non-geometric catalog. A non-geometric candidate must also
// pass on top of the whole geometry (at the step's rate, without the Bonferroni factor):
// an effect that only explains what some DH parameter would is not named (it would soak
// up a geometric error). At most `max_singles` single geometric terms are named; beyond
// them, only the whole geometry.
SelectionResult RunSelection(const Problem& pb, const std::vector<Option>& opts, const std::vector<int>& geometry_terms,
                             const FitResult& start, const RobotAuditOptions& o, double alpha,
                             std::set<std::string>* not_identifiable, std::vector<std::string>* notes,
                             NestedFits* nested, const std::function<void(const std::string&)>& say) {
  SelectionResult res;
  res.cur = start;
  const double logN = std::log(static_cast<double>(pb.N));
  std::set<int> taken;
  int singles = 0, effects = 0;
  const auto FreeAll = [&](const FitResult& f, const std::vector<int>& terms) {
    for (int t : terms)
      if (std::find(f.free.begin(), f.free.end(), t) == f.free.end()) return false;
    return true;
  };
  for (int step = 0; step < o.max_geometric_terms + o.max_effects + 1; ++step) {
    // Held-out gains of a step are scored under the current model's noise (CrossValidate).
    res.cv_known = false;
    const bool geometry_free = FreeAll(res.cur, geometry_terms);
    std::vector<int> open;
    for (size_t i = 0; i < opts.size(); ++i) {
      const Option& op = opts[i];
      if (taken.count(static_cast<int>(i))) continue;
      if (op.geometric && op.tier == 0 && singles >= o.max_geometric_terms) continue;
      if (!op.geometric && effects >= o.max_effects) continue;
      if (op.geometric && geometry_free) continue;
      open.push_back(static_cast<int>(i));
    }
    if (open.empty()) break;
    say("step " + std::to_string(step + 1) + ": screening " + std::to_string(open.size()) + " candidates");
    std::vector<std::string> ni;
    std::vector<Screened> sc = Screen(pb, res.cur, opts, open, o.identifiability_tolerance, &ni);
    if (step == 0)
      for (const auto& k : ni) not_identifiable->insert(k);
    const int M = static_cast<int>(sc.size());
    if (sc.empty()) break;
    std::sort(sc.begin(), sc.end(), [&](const Screened& a, const Screened& b) {
      return a.gain - ParamCount(pb, a.terms) * logN > b.gain - ParamCount(pb, b.terms) * logN;
    });
    const auto Threshold = [&](int k) { return ChiSquareThreshold(k, alpha / M); };
    // The whole geometry on top of the current model: the base of the confirmations.
    std::optional<FitResult> with_geometry;
    std::vector<Tried> tried;
    std::vector<std::pair<double, std::string>> unconfirmed;  // BIC gain, note
    for (size_t i = 0; i < sc.size() && static_cast<int>(tried.size()) < o.max_full_fits; ++i) {
      const int k = ParamCount(pb, sc[i].terms);
      const Option& op = opts[sc[i].option];
      if (sc[i].gain < 0.3 * Threshold(k)) continue;
      if (op.geometric && op.tier == 1 && !EnoughData(pb, static_cast<int>(res.cur.free.size()) + k)) continue;
      Tried t = FitCandidate(pb, res.cur, sc[i].option, sc[i].terms);
      t.lr = 2.0 * (t.fit.loglik - res.cur.loglik);
      t.bic = BicGain(t.lr, k, logN);
      if (!nested->Record(t.lr, res.cur.loglik)) {
        notes->push_back(FailedSolveNote(op.key, t.lr));
        say(notes->back());
        continue;
      }
      char b[240];
      std::snprintf(b, sizeof b, "step %d: %s: likelihood ratio %.1f (threshold %.1f), BIC gain %.1f", step + 1,
                    op.key.c_str(), t.lr, Threshold(k), t.bic);
      say(b);
      // Confirmation on top of the whole geometry.
      if (!op.geometric && !geometry_free && !geometry_terms.empty() && t.lr >= Threshold(k)) {
        const std::vector<int> Fg = Union(res.cur.free, geometry_terms);
        if (EnoughData(pb, static_cast<int>(Fg.size()) + k)) {
          if (!with_geometry) {
            with_geometry = FitModel(pb, Fg, res.cur.theta, res.cur.noise);
            nested->Record(2.0 * (with_geometry->loglik - res.cur.loglik), res.cur.loglik);
          }
          const Tried c = FitCandidate(pb, *with_geometry, sc[i].option, sc[i].terms);
          const double lr = 2.0 * (c.fit.loglik - with_geometry->loglik);
          // A ratio below zero within the solver's tolerance is a zero (shown as such, not
          // "-0.0"); beyond it, a failed solve, recorded and shown as it is.
          const bool solved = nested->Record(lr, with_geometry->loglik);
          if (ChiSquareSurvival(lr, k) >= alpha) {
            std::snprintf(b, sizeof b,
                          "%s: likelihood ratio %.1f on the model, but only %.1f on top of every identifiable DH "
                          "parameter: what it explains, the geometry explains too; not named",
                          op.key.c_str(), t.lr, solved ? std::max(lr, 0.0) : lr);
            say(b);
            unconfirmed.push_back({t.bic, b});
            continue;
          }
        }
      }
      tried.push_back(std::move(t));
    }
    // An unconfirmed candidate is worth a note only where it would have led the step.
    const auto NoteUnconfirmed = [&](double named_bic) {
      const auto top = std::max_element(unconfirmed.begin(), unconfirmed.end());
      if (top != unconfirmed.end() && top->first > named_bic) notes->push_back(top->second);
    };
    if (tried.empty()) {
      NoteUnconfirmed(-kInf);
      break;
    }
    std::vector<SelectionCandidate> sel(tried.size());
    for (size_t i = 0; i < tried.size(); ++i) {
      sel[i].k = ParamCount(pb, tried[i].terms);
      sel[i].lr = tried[i].lr;
      sel[i].tier = opts[tried[i].option].tier;
      sel[i].row_loglik.assign(tried[i].fit.row_ll.data(), tried[i].fit.row_ll.data() + pb.N);
    }
    SelectionRule rule;
    rule.alpha = alpha;
    rule.ln_n = logN;
    rule.close_bic = 10.0;
    const StepDecision dec = DecideStep(sel, M, rule, [&](int i) {
      if (!res.cv_known) {
        res.cur_cv = CrossValidate(pb, res.cur, res.cur.noise);
        res.cv_known = true;
      }
      Tried& t = tried[i];
      if (!t.cv_done) {
        say("step " + std::to_string(step + 1) + ": cross-validating " + opts[t.option].key);
        t.cv = CrossValidate(pb, t.fit, res.cur.noise);
        t.cv_done = true;
      }
      sel[i].heldout_row_loglik.assign(t.cv.row_ll.data(), t.cv.row_ll.data() + pb.N);
      return t.cv.loglik - res.cur_cv.loglik;
    });
    NoteUnconfirmed(dec.best >= 0 && dec.outcome != StepOutcome::kNoHeldoutGain ? sel[dec.best].bic_gain : -kInf);
    if (dec.outcome == StepOutcome::kNothingPasses) break;
    if (dec.outcome == StepOutcome::kNoHeldoutGain) {
      char b[200];
      std::snprintf(b, sizeof b,
                    "%s passed the likelihood-ratio test on all data but did not gain held-out log-likelihood "
                    "(%.1f): not named",
                    opts[tried[dec.best].option].key.c_str(), sel[dec.best].heldout_gain);
      notes->push_back(b);
      break;
    }
    Tried& best = tried[dec.best];
    Finding f;
    f.option = best.option;
    f.terms = best.terms;
    f.lr = best.lr;
    f.bic = best.bic;
    f.ll_gain = best.cv.loglik - res.cur_cv.loglik;
    f.rms_before = res.cur_cv.rms;
    f.base_cv_loglik = res.cur_cv.loglik;
    f.rms_after = best.cv.rms;
    f.tau_sigma = best.tau_sigma;
    f.undecided = dec.outcome == StepOutcome::kUndecided;
    // The best is in the model; the others of an undecided group stay candidates: if one
    // still earns its place on top of the best, it was not an alternative but a second
    // effect (both then named, below).
    taken.insert(best.option);
    if (f.undecided)
      for (int i : dec.group) f.group.push_back(tried[i]);
    const Option& bo = opts[best.option];
    if (bo.geometric && bo.tier == 0) ++singles;
    if (!bo.geometric) ++effects;
    // A candidate named now that stood in an earlier undecided group beside that group's
    // best: both earn their places, so that group is decided.
    if (!f.undecided)
      for (Finding& g : res.findings)
        if (g.undecided)
          for (size_t m = 1; m < g.group.size(); ++m)
            if (g.group[m].option == f.option) g.undecided = false;
    res.findings.push_back(f);
    res.cur = best.fit;
    res.cur_cv = best.cv;
    RetestFlexible(pb, opts, o, alpha, &taken, &res, notes, nested, say);
  }
  return res;
}
// Poses that best separate two fitted models: their predicted tool difference against
// the noise, over poses drawn within the joint limits and near the logged ones.
RobotAuditResult::NextPoses SeparatingPoses(const Problem& pb, const RobotLog& log, const Tried& A, const Tried& B,
                                            const std::string& la, const std::string& lb, int count) {
  RobotAuditResult::NextPoses np;
  np.a = la;
  np.b = lb;
  if (count <= 0) return np;
  const RobotModel& robot = *pb.robot;
  Rng rng(20261204);
  const Eigen::MatrixXd Li = WhiteningOf(A.fit.noise);
  const RowData& last = pb.rows.back();
  struct Cand {
    Eigen::VectorXd q;
    double score;
    Vec3 pa, pb;
    RowData row;              // the pose's row (B's prediction as its measurement)
    Eigen::MatrixXd J[2];     // whitened Jacobian of A's (0) and B's (1) residual
    Eigen::VectorXd w[2];     // whitened difference: the other model's prediction minus this one's
  };
  std::vector<Cand> cands;
  for (int k = 0; k < 4000; ++k) {
    Eigen::VectorXd q = k % 2 ? log.rows[static_cast<int>(rng.Uniform() * pb.N) % pb.N].q : Eigen::VectorXd::Zero(pb.n);
    const int redraw = k % 2 ? 1 + static_cast<int>(rng.Uniform() * 2) : pb.n;
    for (int r = 0; r < redraw; ++r) {
      const int j = k % 2 ? static_cast<int>(rng.Uniform() * pb.n) % pb.n : r;
      const auto [lo, hi] = SamplingRange(robot.Joints()[j]);
      q[j] = rng.Uniform(lo, hi);
    }
    if (robot.HasMimicJoints()) q = robot.ChainValues(robot.ActuatedValues(q));  // mimic joints follow
    RowData row;
    row.q = q;
    row.c = last.c;
    row.c.move_direction = Eigen::VectorXd::Zero(pb.n);
    row.c.joint_velocity.resize(0);
    row.c.gravity_lever = GravityLever(robot, q);
    row.c.gravity_lever.col(2 * pb.n) *= pb.payload_factor;
    row.c.gravity_torque = robot.HasMasses() ? GravityTorque(robot, q, pb.payload)
                                             : Eigen::VectorXd(GravityTorquePerKg(robot, q) * pb.payload_factor);
    // B's prediction is the "measurement": A's residual is then the difference.
    double e[6];
    row.p.setZero();
    row.R.setIdentity();
    RowResidual(pb, row, B.fit.theta.data(), e);
    const Vec3 pbv(e[0], e[1], e[2]);
    row.p = pbv;
    if (pb.six) {
      // R_meas = R_pred_B: with R_meas = I the residual's rotation is Log(R_pred_B).
      row.R = ExpSO3(Vec3(e[3], e[4], e[5]));
    }
    RowResidual(pb, row, A.fit.theta.data(), e);
    Eigen::VectorXd d(pb.m);
    for (int a = 0; a < pb.m; ++a) d[a] = e[a];
    cands.push_back({q, (Li * d).squaredNorm(), pbv + Vec3(e[0], e[1], e[2]), pbv, row, {}, {}});
  }
  std::sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) { return a.score > b.score; });
  if (cands.size() > 300) cands.resize(300);

  // What a set of poses decides once measured: each model is refitted (registration, tool,
  // every parameter it holds) to the other's predictions on the logged rows and r readings
  // of each new pose, linearised; the whitened misfit left is the noncentrality of their
  // likelihood ratio. Side 0 fits A to B, side 1 B to A; the smaller decides.
  const Tried* M[2] = {&A, &B};
  Eigen::MatrixXd Jold[2];
  Eigen::VectorXd wold[2];
  for (int side = 0; side < 2; ++side) {
    const std::vector<int>& F = M[side]->fit.free;
    Jold[side].resize(static_cast<Eigen::Index>(pb.N) * pb.m, F.size());
    wold[side].resize(static_cast<Eigen::Index>(pb.N) * pb.m);
    for (int i = 0; i < pb.N; ++i) {
      // The other model's prediction minus this one's: (R_other - R_this) at row i.
      const Eigen::VectorXd d = (M[1 - side]->fit.R.row(i) - M[side]->fit.R.row(i)).transpose();
      wold[side].segment(static_cast<Eigen::Index>(i) * pb.m, pb.m) = Li * d;
      for (size_t c = 0; c < F.size(); ++c)
        for (int a = 0; a < pb.m; ++a) {
          double v = 0;
          for (int b = 0; b <= a; ++b) v += Li(a, b) * pb.J[b](i, F[c]);
          Jold[side](static_cast<Eigen::Index>(i) * pb.m + a, c) = v;
        }
    }
  }
  // Each candidate's whitened difference and Jacobians (central differences; the models
  // are linear in their parameters at these sizes).
  for (Cand& c : cands) {
    for (int side = 0; side < 2; ++side) {
      const std::vector<int>& F = M[side]->fit.free;
      Eigen::VectorXd th = M[side]->fit.theta;
      double e0[6], ep[6], em[6];
      RowData row = c.row;
      RowResidual(pb, row, M[1 - side]->fit.theta.data(), e0);
      row.p = Vec3(e0[0], e0[1], e0[2]) + row.p;  // the other model's prediction measured
      if (pb.six) row.R = ExpSO3(Vec3(e0[3], e0[4], e0[5])) * row.R;
      RowResidual(pb, row, th.data(), e0);
      Eigen::VectorXd d(pb.m);
      for (int a = 0; a < pb.m; ++a) d[a] = -e0[a];
      c.w[side] = Li * d;
      Eigen::MatrixXd J(pb.m, F.size());
      for (size_t k = 0; k < F.size(); ++k) {
        const double h = 1e-6 * std::max(1.0, std::abs(th[F[k]]));
        const double t0 = th[F[k]];
        th[F[k]] = t0 + h;
        RowResidual(pb, row, th.data(), ep);
        th[F[k]] = t0 - h;
        RowResidual(pb, row, th.data(), em);
        th[F[k]] = t0;
        for (int a = 0; a < pb.m; ++a) J(a, k) = (ep[a] - em[a]) / (2 * h);
      }
      c.J[side] = Li * J;
    }
  }
  const auto Noncentrality = [&](const std::vector<const Cand*>& S, double r) {
    double worst = kInf;
    for (int side = 0; side < 2; ++side) {
      Eigen::MatrixXd H = Jold[side].transpose() * Jold[side];
      Eigen::VectorXd g = Jold[side].transpose() * wold[side];
      double tot = wold[side].squaredNorm();
      for (const Cand* c : S) {
        H += r * c->J[side].transpose() * c->J[side];
        g += r * c->J[side].transpose() * c->w[side];
        tot += r * c->w[side].squaredNorm();
      }
      worst = std::min(worst, std::max(0.0, tot - g.dot(SolveScaled(H, g))));
    }
    return worst;
  };
  // Greedy: the pose that adds most to what one reading of each decides, away from the
  // poses taken (no joint within 0.2 of theirs).
  std::vector<const Cand*> S;
  std::vector<bool> used(cands.size(), false);
  while (static_cast<int>(S.size()) < count) {
    int best = -1;
    double best_l = -1;
    for (size_t i = 0; i < cands.size(); ++i) {
      if (used[i]) continue;
      bool far = true;
      for (const Cand* t : S) far &= (t->q - cands[i].q).cwiseAbs().maxCoeff() > 0.2;
      if (!far) continue;
      S.push_back(&cands[i]);
      const double l = Noncentrality(S, 1.0);
      S.pop_back();
      if (l > best_l) best_l = l, best = static_cast<int>(i);
    }
    if (best < 0) break;
    used[best] = true;
    S.push_back(&cands[best]);
  }
  for (const Cand* c : S) np.poses.push_back({c->q, c->pa, c->pb, std::sqrt(c->score)});
  // Readings of each pose for a decision: Vuong's z of the paired log-likelihoods is about
  // (lambda / 2 - offset) / sqrt(lambda), offset = |k_A - k_B| ln(n) / 2 (the BIC correction);
  // the selection decides where z exceeds its tie band, with 90 % power at
  // z_tie + 1.2816: lambda >= (t + sqrt(t^2 + 2 offset))^2.
  const double t = SelectionRule{}.tie_z + 1.2816;
  const double dk = std::abs(ParamCount(pb, A.terms) - ParamCount(pb, B.terms));
  const auto Needed = [&](int r) {
    const double off = 0.5 * dk * std::log(static_cast<double>(pb.N + r * static_cast<int>(S.size())));
    return std::pow(t + std::sqrt(t * t + 2 * off), 2);
  };
  np.noncentrality_logged = Noncentrality({}, 0.0);
  np.readings = 0;
  for (int r = 1; r <= 1000 && !S.empty(); r = r < 10 ? r + 1 : r + std::max(1, r / 5)) {
    const double l = Noncentrality(S, r);
    np.noncentrality = l;
    np.noncentrality_needed = Needed(r);
    if (l >= np.noncentrality_needed) {
      np.readings = r;
      break;
    }
  }
  return np;
}

// A physical bound the data push against (a negative compliance or backlash wanted on top
// of the final model and the whole geometry): said in a note, not named.
void NoteViolatedBounds(const Problem& pb, const std::vector<Option>& opts, const Identifiable& ident,
                        const FitResult& fin, double alpha_selection, const RobotAuditOptions& o,
                        AuditReport* rep_out) {
  AuditReport& rep = *rep_out;
  const bool has_geometry = Union(fin.free, ident.params).size() == fin.free.size();
  const FitResult base = has_geometry ? fin : FitProfiled(pb, Union(fin.free, ident.params), fin.theta, fin.noise);
  std::vector<int> bounded;
  for (size_t i = 0; i < opts.size(); ++i) {
    bool b = false, all_free = true;
    for (int t : opts[i].terms) {
      b |= pb.lower[t] == 0.0;  // a sign constraint (a compliance, a mass, a backlash)
      all_free &= std::find(base.free.begin(), base.free.end(), t) != base.free.end();
    }
    if (b && !all_free) bounded.push_back(static_cast<int>(i));
  }
  std::vector<std::string> ignored;
  for (const Screened& sc : Screen(pb, base, opts, bounded, o.identifiability_tolerance, &ignored)) {
    const int k = ParamCount(pb, sc.terms);
    if (sc.gain < ChiSquareThreshold(k, alpha_selection / std::max<size_t>(1, opts.size()))) continue;
    int worst = 0;
    for (int j = 1; j < sc.estimate.size(); ++j)
      if (sc.estimate[j] / std::max(1e-300, sc.sigma[j]) < sc.estimate[worst] / std::max(1e-300, sc.sigma[worst]))
        worst = j;
    if (!(sc.estimate[worst] < -3.0 * sc.sigma[worst])) continue;
    const Option& op = opts[sc.option];
    const auto names = op.ext.ParameterNames();
    const int blk = std::upper_bound(pb.offset.begin(), pb.offset.end(), sc.terms[worst]) - pb.offset.begin() - 1;
    const int pidx = std::min<int>(sc.terms[worst] - pb.offset[blk], names.size() - 1);
    char nb[600];
    std::snprintf(nb, sizeof nb,
                  "%s: the data ask for a sign no joint can have (%s = %.3g +- %.2g without its bound at 0, "
                  "likelihood ratio %.1f): held at 0 and not named; a counterbalance spring, masses in the robot "
                  "file that are too large, or an effect the catalog lacks would do this",
                  op.key.c_str(), names[pidx].c_str(), sc.estimate[worst], sc.sigma[worst], sc.gain);
    rep.notes.push_back(nb);
  }
}

}  // namespace mcms::robot_audit
