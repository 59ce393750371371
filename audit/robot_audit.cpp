#include "audit/robot_audit.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numeric>
#include <optional>
#include <set>
#include <sstream>

#include "audit/model_selection.h"
#include "audit/robot_audit_problem.h"
#include "audit/robot_audit_residuals.h"
#include "audit/robot_audit_selection.h"
#include "core/format.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/statistics.h"

namespace mcms {

bool RobotAuditOptions::IsValid(std::string* why) const {
  const auto fail = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (!(false_alarm > 0 && false_alarm < 0.5)) return fail("false_alarm must be in (0, 0.5)");
  if (folds < 2) return fail("folds must be at least 2");
  if (max_effects < 0) return fail("max_effects must be >= 0");
  if (max_geometric_terms < 0) return fail("max_geometric_terms must be >= 0");
  if (max_full_fits < 1) return fail("max_full_fits must be >= 1");
  if (!(repeat_tolerance >= 0)) return fail("repeat_tolerance must be >= 0");
  if (!(identifiability_tolerance > 0 && identifiability_tolerance < 1))
    return fail("identifiability_tolerance must be in (0, 1)");
  if (next_poses < 0) return fail("next_poses must be >= 0");
  for (const auto& n : only) {
    const auto e = EffectFromName(n);
    if (!e) return fail("'" + n + "' is not in the catalog of effects");
    if (Info(*e).sensor != SensorKind::kRobot && *e != Effect::kClockOffset)
      return fail("'" + n + "' is not a robot effect (or clock_offset)");
    if (*e == Effect::kLinkCompliance || *e == Effect::kSegmentPlay || *e == Effect::kAxisTilt)
      return fail("'" + n + "' is seen by tilt sensors on the chain, not by the positions: the audit names it from "
                  "the log's accelerometer readings");
  }
  return true;
}

namespace {

using namespace robot_audit;

std::string Fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

// Where `geometry` acts, as reports name it.
std::string GeometryWhere(const RobotModel& robot) { return Extension{Effect::kGeometry, -1, 0}.Where(robot); }

// Whether a row of the problem carries a measured tilt (issue 52); the problem without them.
bool HasTilt(const Problem& pb) {
  for (const RowData& r : pb.rows)
    if (!(r.tilt.R == Mat3::Identity() && r.tilt.t == Vec3::Zero())) return true;
  return false;
}
Problem WithoutTilt(Problem pb) {
  for (RowData& r : pb.rows) r.tilt = Pose::Identity();
  return pb;
}

// Per row of another session, each measured point as the model theta predicts it (the fit's
// placement): the rigid body's points, or the one point.
std::vector<std::vector<Vec3>> PointPredictions(const Problem& pv, const Eigen::VectorXd& theta) {
  std::vector<std::vector<Vec3>> e(pv.N);
  for (int i = 0; i < pv.N; ++i) {
    const Pose T = PredictedTool(pv, pv.rows[i], theta);
    if (pv.body_points.empty()) {
      e[i].push_back(T.t);
    } else {
      for (int k = 0; k < static_cast<int>(pv.body_points.size()); ++k) e[i].push_back(T * pv.body_points[k]);
    }
  }
  return e;
}

// ---------------------------------------------------------------------------------
// Reporting

// The SI unit of parameter k of a catalog effect of the robot (for the text's mm and mrad).
std::string UnitOf(const RobotModel& robot, const Extension& e, int k) {
  const bool rev = e.index < 0 || e.index >= robot.NumJoints() || robot.Joints()[e.index].type == JointType::kRevolute;
  switch (e.effect) {
    case Effect::kJointOffset:
    case Effect::kBacklash: return rev ? "rad" : "m";
    case Effect::kLinkLength: return "m";
    case Effect::kLinkTwist: return "rad";
    case Effect::kErrorMotion: return k % 6 < 3 ? "rad" : "m";
    case Effect::kThermalDrift: return e.variant == 0 && k == 1 ? "s" : "";
    case Effect::kClockOffset: return "s";
    default: return "";
  }
}

// The effect of a finding with its sizes from `fit`.
AuditEffect EffectOf(const Problem& pb, const Option& op, const std::vector<int>& terms, const FitResult& fit,
                     double tau_sigma, const Identifiable& ident) {
  AuditEffect e;
  e.name = Name(op.ext.effect);
  e.where = op.ext.Where(*pb.robot);
  if (op.ext.effect == Effect::kGeometry) {
    // Every identifiable geometric parameter by its calib-robot name, and the held ones.
    e.where = GeometryWhere(*pb.robot);
    for (int p : ident.params) {
      const std::string nm = GeometryName(pb, p);
      e.parameters.push_back({nm, fit.theta[p]});
      e.sigma.push_back({nm, SigmaOf(fit, p)});
      e.units.push_back(GeometryParameterIsAngle(*pb.robot, p - pb.offset[pb.geometry]) ? "rad" : "m");
    }
    e.held = ident.held;
    return e;
  }
  const auto names = op.ext.ParameterNames();
  const int k = std::upper_bound(pb.offset.begin(), pb.offset.end(), terms.front()) - pb.offset.begin() - 1;
  const bool geometric = k == pb.geometry;
  for (int p : terms) {
    const std::string name = geometric ? names.front() : names[p - pb.offset[k]];
    if (AtBound(fit, p)) {
      const bool low = std::abs(fit.theta[p] - pb.lower[p]) <= std::abs(fit.theta[p] - pb.upper[p]);
      const char* why = op.ext.effect == Effect::kGravityCompliance
                            ? "no joint sags by more than 0.1 rad or 5 mm under the arm's weight"
                            : "no gear ratio is off by more, no joint has more play";
      e.held.push_back({name, low && pb.lower[p] == 0.0
                                  ? "at its physical bound 0 (no negative mass, compliance or backlash)"
                                  : "at its physical bound " + Num4(low ? pb.lower[p] : pb.upper[p]) + " (" + why +
                                        "): the data ask for more than a physical " + name});
      continue;
    }
    e.parameters.push_back({name, fit.theta[p]});
    e.sigma.push_back({name, SigmaOf(fit, p)});
    e.units.push_back(geometric ? (GeometryParameterIsAngle(*pb.robot, p - pb.offset[k]) ? "rad" : "m")
                                : UnitOf(*pb.robot, op.ext, p - pb.offset[k]));
  }
  if (pb.warmup >= 0 && terms.front() == pb.warmup) {
    e.parameters.push_back({names[1], fit.theta[pb.warmup + 1]});
    e.sigma.push_back({names[1], tau_sigma});
    e.units.push_back("s");
  }
  return e;
}

RobotAuditFit ToFit(const Problem& pb, const FitResult& f) {
  RobotAuditFit r;
  for (size_t k = 0; k < pb.blocks.size(); ++k) {
    const int np = pb.blocks[k].NumParameters();
    bool any = false;
    for (int j = 0; j < np; ++j) any |= std::find(f.free.begin(), f.free.end(), pb.offset[k] + j) != f.free.end();
    if (!any) continue;
    r.extensions.push_back(pb.blocks[k]);
    std::vector<double> p(np), s(np);
    for (int j = 0; j < np; ++j) {
      p[j] = f.theta[pb.offset[k] + j];
      s[j] = SigmaOf(f, pb.offset[k] + j);
    }
    r.parameters.push_back(p);
    r.sigmas.push_back(s);
  }
  const Mat3 Rb = ExpSO3(Vec3(f.theta[0], f.theta[1], f.theta[2]));
  r.T_meas_base = Pose{Rb * pb.base0.R, pb.base0.t + Vec3(f.theta[3], f.theta[4], f.theta[5])};
  const Mat3 Rt = pb.six ? ExpSO3(Vec3(f.theta[9], f.theta[10], f.theta[11])) : Mat3::Identity();
  r.T_flange_tool = Pose{Rt * pb.tool0.R, pb.tool0.t + Vec3(f.theta[6], f.theta[7], f.theta[8])};
  r.noise = f.noise;
  r.residuals = f.R;
  r.loglik = f.loglik;
  return r;
}

// The robot description with what it can hold of the fit: the geometric corrections (in
// the DH table, or folded into a URDF chain's origins) and error motion; the tool as fitted.
RobotModel ExtendedRobot(const Problem& pb, const FitResult& f, std::vector<std::string>* notes,
                         const std::vector<Extension>& named) {
  const int g0 = pb.offset[pb.geometry];
  const RobotModel robot = WithGeometryErrors(*pb.robot, f.theta.segment(g0, pb.robot->NumGeometryParameters()));
  std::vector<Joint> joints = robot.Joints();
  for (size_t k = 0; k < pb.blocks.size(); ++k) {
    const Extension& e = pb.blocks[k];
    if (e.effect != Effect::kErrorMotion) continue;
    bool any = false;
    for (int a = 0; a < 12; ++a) any |= f.theta[pb.offset[k] + a] != 0.0;
    if (!any) continue;
    Joint& j = joints[e.index];
    if (j.Harmonics() < 1) {
      j.error_motion_sin.push_back(Vec6::Zero());
      j.error_motion_cos.push_back(Vec6::Zero());
    }
    for (int a = 0; a < 6; ++a) {
      j.error_motion_sin[0][a] += f.theta[pb.offset[k] + a];
      j.error_motion_cos[0][a] += f.theta[pb.offset[k] + 6 + a];
    }
  }
  for (const Extension& e : named)
    if (e.effect != Effect::kErrorMotion && e.effect != Effect::kGeometry && e.effect != Effect::kJointOffset &&
        e.effect != Effect::kLinkLength && e.effect != Effect::kLinkTwist)
      notes->push_back(e.Label(*pb.robot) + " is not a term of the robot description file: robot.yaml holds the rest");
  if (!robot.HasDhTerms())
    for (const Joint& j : joints)
      if (j.Harmonics() > 0) {
        notes->push_back("joint " + j.name + "'s error motion is in robot.yaml; a URDF cannot hold it (robot.urdf "
                         "has the geometry only)");
        break;
      }
  RobotModel m = robot.WithJoints(joints);
  m.SetT_flange_tool(ToFit(pb, f).T_flange_tool);
  return m;
}

// The residual without a named finding along its direction, and the finding itself, per
// measurement against the covariate the effect depends on.
RobotAuditResult::EffectPlot EffectPlotOf(const Problem& pb, const RobotLog& log, const std::vector<Covariate>& cov,
                                          const FitResult& fin, const std::string& label, const std::vector<int>& terms,
                                          const Extension& ext) {
  RobotAuditResult::EffectPlot pl;
  pl.effect = label;
  pl.covariate = CovariateOf(*pb.robot, ext, log.has_temperature);
  Eigen::VectorXd th = fin.theta;
  for (int p : terms) th[p] = pb.theta0[p];
  Eigen::MatrixXd Rwithout;
  Exact(pb, th, AllRows(pb), &Rwithout);
  const Covariate* cv = nullptr;
  for (const auto& c : cov)
    if (c.name == pl.covariate) cv = &c;
  for (int i = 0; i < pb.N; ++i) {
    const Vec3 d = (Rwithout.row(i).leftCols(3) - fin.R.row(i).leftCols(3)).transpose();
    const double nd = d.norm();
    const Vec3 u = nd > 0 ? Vec3(d / nd) : Vec3::UnitX();
    pl.x.push_back(cv ? cv->v[i] : log.rows[i].time_s);
    pl.residual_before.push_back(Rwithout.row(i).leftCols(3).dot(u.transpose()));
    pl.effect_size.push_back(nd);
  }
  return pl;
}

// The other session's plots: point 1's error per posture for the registration, the
// geometry and the final model; per named cause, the error without it and with it along
// the direction it moves the point, against its covariate on that session's rows.
void AddValidationPlots(const RobotModel& robot, const RobotLog& v, const Problem& pv, const SessionScore& s,
                        const std::vector<std::pair<std::string, Extension>>& causes,
                        std::vector<RobotAuditResult::ValidationPlot>* out) {
  const auto Model = [&](const std::string& name) -> const ModelScore* {
    for (const ModelScore& m : s.models)
      if (m.model == name) return &m;
    return nullptr;
  };
  const std::string session = std::filesystem::path(s.log).filename().string();
  RobotAuditResult::ValidationPlot all;
  all.session = s.log;
  all.title = session + " (frozen): point 1's error per posture";
  all.covariate = "posture (row of " + session + ")";
  for (int i = 0; i < s.rows; ++i) all.x.push_back(i + 1);
  for (const char* name : {"nominal", "registration", "geometry", "final"})
    if (const ModelScore* m = Model(name)) {
      std::vector<double> y;
      for (const auto& e : m->errors) y.push_back(e.empty() ? std::nan("") : e[0].norm() * 1e3);
      all.series.push_back({name, y});
    }
  out->push_back(all);
  const ModelScore* fin = Model("final");
  if (!fin) return;
  for (const auto& [label, e] : causes) {
    const ModelScore* wo = Model("final without " + label);
    if (!wo) continue;
    RobotAuditResult::ValidationPlot p;
    p.session = s.log;
    p.title = label + " on " + session + " (frozen): point 1's error along it";
    p.covariate = CovariateOf(robot, e, v.has_temperature);
    std::vector<double> before, effect, after;
    for (int i = 0; i < s.rows && i < pv.N; ++i) {
      if (wo->errors[i].empty() || fin->errors[i].empty()) continue;
      double x = v.rows[i].time_s;
      if (e.effect == Effect::kGravityCompliance) x = pv.rows[i].c.gravity_torque[e.index];
      if (e.effect == Effect::kBacklash) x = pv.rows[i].c.move_direction[e.index];
      if (e.effect == Effect::kJointScale || e.effect == Effect::kErrorMotion) x = v.rows[i].q[e.index];
      // Along the cause's direction, signed by its covariate: a cause proportional to it
      // reads as a line through 0, a step (backlash) as two levels.
      const Vec3 d = wo->errors[i][0] - fin->errors[i][0];
      const Vec3 u = (d.norm() > 0 ? Vec3(d.normalized()) : Vec3::UnitX()) * (x < 0 ? -1.0 : 1.0);
      p.x.push_back(x);
      before.push_back(wo->errors[i][0].dot(u) * 1e3);
      effect.push_back(d.dot(u) * 1e3);
      after.push_back(fin->errors[i][0].dot(u) * 1e3);
    }
    p.series = {{"final model without it", before}, {"what it predicts", effect}, {"final model", after}};
    out->push_back(p);
  }
}

// Which masses the gravity-compliance candidates assume and which they fit (issue 35):
// the reader of a report that names the arm's weight must know whether its torque came
// from the robot file or from the log.
std::string MassesNote(const RobotModel& robot, const RobotLog& log, const std::vector<Option>& others) {
  bool tested = false;
  for (const Option& op : others) tested = tested || op.ext.effect == Effect::kGravityCompliance;
  if (!tested) return "gravity compliance not tested (not in the catalog of this audit)";
  const std::string payload =
      log.has_payload ? "the log's payload column adds its weight at the tool point"
                      : "the log has no payload column: no payload beyond the tool's mass is assumed";
  char b[600];
  if (robot.HasMasses()) {
    double total = 0;
    for (const Joint& j : robot.Joints()) total += *j.mass_kg;
    std::snprintf(b, sizeof b,
                  "gravity compliance: the links' masses are the robot file's (%.3g kg in all; the tool %.3g kg), "
                  "so each joint's gravity torque is known and only its compliance is fitted (>= 0, sagging the "
                  "joint by at most 0.1 rad or 5 mm); %s",
                  total, robot.Tool().mass_kg, payload.c_str());
  } else {
    std::snprintf(b, sizeof b,
                  "gravity compliance: the robot file gives no masses, so each joint's gravity torque is fitted as "
                  "lumped mass moments (the tool point and the link frames outboard of the joint, each >= 0 and "
                  "none sagging the joint by more than 0.1 rad or 5 mm alone) times its compliance; %s",
                  log.has_payload ? "the tool point's moment scales with the log's payload column"
                                  : "the log has no payload column: the tool point's moment is one constant");
  }
  return b;
}

// The robot audit's state, through its phases in order (AuditRobot): 1. the problem, the
// nominal fit, one Jacobian and the residual tests; 2. the selection over the catalog;
// 3. the final model (pruning, named only what predicts, what remains); 4. the report;
// 5. the other sessions scored frozen.
struct RobotAuditRun {
  RobotAuditRun(const RobotModel& robot_in, const RobotLog& log_in, const RobotAuditOptions& o_in,
                const std::vector<RobotLog>& validate_in, RobotAuditResult* result_in)
      : robot(robot_in), log(log_in), o(o_in), validate(validate_in), result(*result_in), rep(result_in->report),
        say([&o_in](const std::string& s) {
          if (o_in.progress) o_in.progress(s);
        }) {
    rep.mode = "robot";
    rep.rms_unit = "m";
  }
  void NominalFitAndTests();
  void Selection();
  void FinalModel();
  void Report();
  void OtherSessions();

  // The model's free parameters: the base, and the terms of every finding kept by `keep`.
  std::vector<int> TermsOf(const std::function<bool(const Finding&)>& keep) const {
    std::vector<int> t = model_base;
    for (const Finding& f : sel.findings)
      if (!f.dropped && keep(f)) t = Union(t, f.terms);
    return t;
  }
  // The selection's model refitted with free parameters F (the others at the nominal).
  FitResult Refit(const std::vector<int>& F) const {
    Eigen::VectorXd th = sel.cur.theta;
    for (int p = pb.NumBase(); p < pb.P; ++p)
      if (std::find(F.begin(), F.end(), p) == F.end()) th[p] = pb.theta0[p];
    return FitProfiled(pb, F, th, sel.cur.noise);
  }
  bool IsWhole(const Finding& f) const { return opts[f.option].geometric && opts[f.option].tier == 1; }
  bool IsSingle(const Finding& f) const { return opts[f.option].geometric && opts[f.option].tier == 0; }

  const RobotModel& robot;
  const RobotLog& log;
  const RobotAuditOptions& o;
  const std::vector<RobotLog>& validate;
  RobotAuditResult& result;
  AuditReport& rep;
  const std::function<void(const std::string&)> say;

  Problem pb;
  std::vector<Option> geo_opts, other_opts;  // the catalog: geometric terms, the other effects
  std::vector<int> base_free;                // registration and tool, less what is not identifiable
  FitResult nominal;
  double logN = 0, alpha_tests = 0, alpha_selection = 0;
  std::vector<Covariate> cov;
  std::set<std::string> not_identifiable;
  Identifiable ident;
  std::vector<Option> opts;     // the selection's candidates
  SelectionResult sel;
  std::vector<int> model_base;  // what every model of the selection frees
  std::optional<AuditEffect> unconfirmed_geometry;
  FitResult fin;                // the final model
};

void RobotAuditRun::NominalFitAndTests() {
  // 1. The problem, the nominal fit, one Jacobian, the residual tests.
  pb = MakeProblem(robot, log, o);
  // geo_opts, other_opts: the catalog
  MakeLayout(&pb, log, o, &geo_opts, &other_opts, &rep.notes);
  rep.notes.push_back(MassesNote(robot, log, other_opts));
  {
    // The linearised problem holds the Jacobian (m N x P) and the normal matrices of every
    // fold (m^2 (K + 1) of P x P): bounded before the work, with what to do instead.
    const double P = pb.P, m = pb.m, bytes = 8.0 * (m * pb.N * P + m * m * (2 * pb.K + 1) * P * P);
    if (pb.N > kMaxAuditRows)
      Throw("audit robot: ", log.source.empty() ? std::string("the robot log") : log.source.string(), " has ", pb.N,
            " measurements, more than the ", kMaxAuditRows,
            " the audit takes (core/limits.h; its cost grows with them, and a few hundred poses identify a robot): "
            "thin the log (every k-th row) or audit its sessions apart (--validate scores one against another)");
    if (bytes > static_cast<double>(kMaxAuditBytes))
      Throw("audit robot: ", log.source.empty() ? std::string("the robot log") : log.source.string(), " (",
            pb.N, " measurements) with the catalog of robot '", robot.Name(), "' (", robot.NumJoints(),
            " joints, ", pb.P, " parameters) would take ", std::lround(bytes / (1 << 20)),
            " MB to linearise, beyond the ", kMaxAuditBytes >> 20,
            " MB limit (core/limits.h): test fewer effects (--only), audit a shorter chain (--tip-link), or thin "
            "the log (a few hundred poses identify a robot)");
  }
  say("nominal fit");
  const Eigen::MatrixXd noise0 = FitNominal(&pb);
  say("linearising " + std::to_string(pb.P) + " parameters over " + std::to_string(pb.N) + " measurements");
  Linearize(&pb);
  base_free = pb.BaseParams();
  // A registration or tool parameter these poses cannot identify is held where it starts
  // (the robot file's tool): a free one wanders along the degeneracy.
  Identifiable ident0 = GeometryIdentifiability(pb, noise0, o.identifiability_tolerance);
  for (const auto& [p, why] : ident0.held_base) {
    std::erase(base_free, p);
    pb.theta0[p] = 0.0;
    rep.notes.push_back("held at the robot file's value, not identifiable from these measurements: " + why);
  }
  nominal = FitModel(pb, base_free, pb.theta0, noise0);
  const int N = pb.N;
  logN = std::log(static_cast<double>(N));
  rep.nominal_n = static_cast<long>(N) * pb.m;
  cov = Covariates(robot, log, pb);
  alpha_tests = o.false_alarm / 2.0;
  const double lof =
      TestResiduals(log, pb, nominal, cov, alpha_tests, static_cast<int>(base_free.size()),
                    JitterTolerance(robot, o.repeat_tolerance), &rep);
  rep.nominal_chi2_per_dof = std::isfinite(lof) ? lof : 1.0;
}

void RobotAuditRun::Selection() {
  // 2. Greedy selection over the catalog: the DH parameters these poses identify one by
  //    one and all at once ("geometry first": a real robot has all of them a little off),
  //    the other effects confirmed on top of the whole geometry.
  // not_identifiable: the catalog's effects these measurements cannot identify
  ident = GeometryIdentifiability(pb, nominal.noise, o.identifiability_tolerance);
  // The whole geometry's fit: a parameter it drives to its bound (a placement off by more
  // than any calibration finds, where the poses barely see it and an unmodelled cause pulls)
  // is held at the robot file's value, and the rest fitted again. Where that fit is far from
  // the nominal (a robot whose description is off by millimetres over metres of chain), the
  // one Jacobian is taken again there, where every later model lies near, so that their
  // fits converge on it.
  if (GeometryWanted(o) && !ident.params.empty() &&
      EnoughData(pb, static_cast<int>(base_free.size() + ident.params.size()))) {
    FitResult g = FitModel(pb, Union(base_free, ident.params), nominal.theta, nominal.noise);
    for (int round = 0; round < 8; ++round) {
      std::vector<int> at;
      for (int p : ident.params)
        if (AtBound(g, p)) at.push_back(p);
      if (at.empty()) break;
      for (int p : at) {
        std::erase(ident.params, p);
        char b[200];
        std::snprintf(b, sizeof b,
                      "held at the robot file's value: its fit goes to the bound of %.2g (no placement is off by "
                      "more), where the poses barely see it and another cause pulls",
                      std::max(std::abs(pb.lower[p]), std::abs(pb.upper[p])));
        ident.held.push_back({GeometryName(pb, p), b});
      }
      g = FitModel(pb, Union(base_free, ident.params), nominal.theta, nominal.noise);
    }
    if (g.nonlinear) {
      say("the geometry's fit is far from the nominal: linearising again there");
      Linearize(&pb, &g.theta);
    }
  }
  opts.clear();
  for (const Option& op : geo_opts)
    if (std::find(ident.params.begin(), ident.params.end(), op.terms.front()) != ident.params.end()) opts.push_back(op);
  if (Wanted(o, Effect::kGeometry) && ident.params.size() > 1) {
    Option g{"geometry at " + GeometryWhere(robot), pb.blocks[pb.geometry], ident.params, 1, true};
    opts.push_back(g);
  }
  opts.insert(opts.end(), other_opts.begin(), other_opts.end());
  alpha_selection = o.false_alarm / 2.0;
  const std::vector<int> geometry_terms = GeometryWanted(o) ? ident.params : std::vector<int>{};
  const RobotAuditOptions& so = o;
  sel =
      RunSelection(pb, opts, geometry_terms, nominal, so, alpha_selection, &not_identifiable, &rep.notes,
                   &rep.nested, say);

  // 2b. Geometry present but not confirmed held out: the whole identifiable geometry still
  //     passes the likelihood-ratio test and BIC on top of what was named, but its
  //     held-out test fails (a log of few postures cannot confirm tens of parameters by
  //     cross-validation: each fold's geometry extrapolates to postures it did not see).
  //     Every real robot has its geometry a little off, and a physical effect fitted
  //     without it soaks up geometric error: the non-geometric effects are selected again
  //     on top of it, and the final model includes it.
  model_base = base_free;
  unconfirmed_geometry.reset();
  const auto FreeAll = [](const FitResult& f, const std::vector<int>& terms) {
    for (int t : terms)
      if (std::find(f.free.begin(), f.free.end(), t) == f.free.end()) return false;
    return true;
  };
  if (GeometryWanted(o) && ident.params.size() > 1 && !FreeAll(sel.cur, ident.params)) {
    const std::vector<int> Fg = Union(sel.cur.free, ident.params);
    const double k = static_cast<double>(Fg.size() - sel.cur.free.size());
    if (EnoughData(pb, static_cast<int>(Fg.size()))) {
      const FitResult g = FitModel(pb, Fg, sel.cur.theta, sel.cur.noise);
      const double lr = 2.0 * (g.loglik - sel.cur.loglik);
      rep.nested.Record(lr, sel.cur.loglik);
      if (EarnsPlace(lr, k, alpha_selection / std::max<size_t>(1, opts.size()), logN)) {
        say("the whole geometry passes on top of the named effects but not held out: selecting on top of it");
        model_base = Union(base_free, ident.params);
        const FitResult start = FitModel(pb, model_base, nominal.theta, nominal.noise);
        const HeldOut before = CrossValidate(pb, nominal, nominal.noise), after = CrossValidate(pb, start, nominal.noise);
        AuditEffect e = EffectOf(pb, Option{"geometry at " + GeometryWhere(robot), pb.blocks[pb.geometry], ident.params, 1, true},
                                 ident.params, start, 0.0, ident);
        e.heldout_rms_before = before.rms;
        e.heldout_rms_after = after.rms;
        e.heldout_loglik_gain = after.loglik - before.loglik;
        e.bic_gain = BicGain(2.0 * (start.loglik - nominal.loglik), static_cast<double>(ident.params.size()), logN);
        unconfirmed_geometry = e;
        char b[400];
        std::snprintf(b, sizeof b,
                      "geometry: the whole identifiable geometry (%zu parameters) earns its place on all data "
                      "(likelihood ratio %.1f on top of the effects named first, BIC gain %.1f over the nominal) but "
                      "not on held-out data (gain %.1f): %d measurements cannot confirm that many parameters by "
                      "cross-validation. The non-geometric effects were selected again on top of it, and the final "
                      "model includes it",
                      ident.params.size(), lr, e.bic_gain, e.heldout_loglik_gain, pb.N);
        // The first pass's "geometry ... not named" is superseded.
        std::erase_if(rep.notes, [](const std::string& n) {
          return n.rfind("geometry at ", 0) == 0 && n.find("not named") != std::string::npos;
        });
        rep.notes.push_back(b);
        std::vector<Option> physical;
        for (const Option& op : opts)
          if (!op.geometric) physical.push_back(op);
        opts = physical;
        sel = RunSelection(pb, opts, {}, start, so, alpha_selection, &not_identifiable, &rep.notes, &rep.nested,
                           say);
      }
    }
  }
}

void RobotAuditRun::FinalModel() {
  // 3. Backward pruning: geometric findings that the later effects make unnecessary.
  say("final fit");
  fin = sel.cur;
  std::string effects;
  for (const Finding& f : sel.findings)
    if (!opts[f.option].geometric) effects += (effects.empty() ? "" : ", ") + opts[f.option].key;
  if (!effects.empty()) {
    const double bar = alpha_selection / std::max<size_t>(1, opts.size());
    while (true) {
      int weakest = -1;
      double wlr = kInf;
      FitResult wfit;
      for (size_t i = 0; i < sel.findings.size(); ++i) {
        const Finding& fi = sel.findings[i];
        if (fi.dropped || !opts[fi.option].geometric) continue;
        // Without it; the whole geometry gives way to the single terms named before it.
        const FitResult f = Refit(TermsOf([&](const Finding& x) { return &x != &fi; }));
        const double lr = 2.0 * (fin.loglik - f.loglik);
        rep.nested.Record(lr, f.loglik);
        const double k = static_cast<double>(Union(f.free, fi.terms).size() - f.free.size());
        if (EarnsPlace(lr, std::max(1.0, k), bar, logN)) continue;
        if (lr < wlr) wlr = lr, weakest = static_cast<int>(i), wfit = f;
      }
      if (weakest < 0) break;
      sel.findings[weakest].dropped = true;
      fin = wfit;
      rep.notes.push_back(opts[sel.findings[weakest].option].key + " was named at first, but once " + effects +
                          " is in the model it no longer earns its place (likelihood ratio " + Fixed(wlr, 1) +
                          "): not named");
    }
  }
  // The final model holds what is named: an undecided group (one of its members, the data
  // cannot tell which) stays out of it until the proposed poses decide it.
  fin = Refit(TermsOf([](const Finding& f) { return !f.undecided; }));
  // 3b. Named only what predicts (issue 51): in the final model, each named effect beyond
  //     the geometry must stay off its physical bounds, at 3 sigma at least, and predict
  //     postures outside the region it was fitted on (blocks of joint space held out, the
  //     final model against the final model without it). The one that fails worst is taken
  //     out, the model refitted, and the others judged again.
  {
    HeldOut fin_posture;
    bool fin_posture_known = false;
    while (true) {
      int out = -1;
      std::string why;
      FitResult out_fit;
      for (size_t i = 0; i < sel.findings.size() && out < 0; ++i) {
        const Finding& fi = sel.findings[i];
        if (fi.dropped || fi.undecided || opts[fi.option].geometric) continue;
        const std::string& key = opts[fi.option].key;
        // Off its bounds: a parameter held at a bound that is not the zero of a sign.
        for (int p : fi.terms)
          if (AtBound(fin, p)) {
            const bool low = std::abs(fin.theta[p] - pb.lower[p]) <= std::abs(fin.theta[p] - pb.upper[p]);
            if (low && pb.lower[p] == 0.0) continue;  // the zero of a compliance, mass or backlash
            why = key + " is at its physical bound (" + Num4(low ? pb.lower[p] : pb.upper[p]) +
                  "): the data ask for more than the physical effect can be; at its bound: not a finding";
            out = static_cast<int>(i);
            break;
          }
        if (out >= 0) break;
        // At 3 sigma at least: the likelihood ratio of the final model over the final model
        // without it, as the two-sided normal deviate of its chi-square p-value (a Wald
        // statistic is no measure where a nuisance is profiled: a warm-up's time constant).
        const FitResult wo = Refit(TermsOf([&](const Finding& x) { return &x != &fi && !x.undecided; }));
        const double lr = 2.0 * (fin.loglik - wo.loglik);
        rep.nested.Record(lr, wo.loglik);
        const double z = SigmaOfTwoSidedP(ChiSquareSurvival(std::max(0.0, lr), ParamCount(pb, fi.terms)));
        if (z < 3.0) {
          char b[300];
          std::snprintf(b, sizeof b,
                        "%s is only %.1f sigma in the final model (likelihood ratio %.1f over the final model "
                        "without it, %d parameters): not named",
                        key.c_str(), z, lr, ParamCount(pb, fi.terms));
          why = b;
          out = static_cast<int>(i);
          break;
        }
        // Predicts postures it was not fitted on.
        if (!fin_posture_known) fin_posture = CrossValidate(pb, fin, fin.noise, true), fin_posture_known = true;
        const HeldOut wo_posture = CrossValidate(pb, wo, fin.noise, true);
        const double gain = fin_posture.loglik - wo_posture.loglik;
        if (!(gain > 0)) {
          char b[400];
          std::snprintf(b, sizeof b,
                        "%s does not predict postures outside those it was fitted on (held out by blocks of joint "
                        "space, the final model with it gains %.1f nats over the final model without it; RMS %.4g -> "
                        "%.4g mm): not named",
                        key.c_str(), gain, wo_posture.rms * 1e3, fin_posture.rms * 1e3);
          why = b;
          out = static_cast<int>(i);
          out_fit = wo;
        }
      }
      if (out < 0) break;
      say(why);
      rep.notes.push_back(why);
      sel.findings[out].dropped = true;
      fin = Refit(TermsOf([](const Finding& f) { return !f.undecided; }));
      fin_posture_known = false;
    }
  }
  NoteViolatedBounds(pb, opts, ident, fin, alpha_selection, o, &rep);
  // What remains unexplained: the residual tests again, on the final model's residuals.
  if (fin.free.size() > base_free.size()) {
    AuditReport after;
    TestResiduals(log, pb, fin, cov, alpha_tests, static_cast<int>(fin.free.size()),
                  JitterTolerance(robot, o.repeat_tolerance), &after, &rep.tests_after_run);
    for (const AuditTest& t : after.tests)
      if (t.failed) rep.tests_after.push_back(t);
  }
}

void RobotAuditRun::Report() {
  // 4. The report.
  std::vector<Extension> named;
  bool geometry_named = false;
  if (unconfirmed_geometry) {
    rep.effects.push_back(*unconfirmed_geometry);
    named.push_back(pb.blocks[pb.geometry]);
    geometry_named = true;
  }
  HeldOut nominal_cv, fin_cv;
  for (const Finding& f : sel.findings) {
    if (f.dropped) continue;
    const Option& op = opts[f.option];
    if (f.undecided) {
      std::vector<std::string> labels;
      std::vector<AuditEffect> sizes;
      for (const Tried& t : f.group) {
        labels.push_back(opts[t.option].key);
        AuditEffect e = EffectOf(pb, opts[t.option], t.terms, t.fit, t.tau_sigma, ident);
        e.heldout_rms_before = f.rms_before;
        e.heldout_rms_after = t.cv_done ? t.cv.rms : std::nan("");
        e.heldout_loglik_gain = t.cv_done ? t.cv.loglik - f.base_cv_loglik : std::nan("");
        e.bic_gain = t.bic;
        sizes.push_back(e);
      }
      rep.undecided.push_back(labels);
      rep.undecided_effects.push_back(sizes);
      if (f.group.size() >= 2)
        result.next_poses.push_back(
            SeparatingPoses(pb, log, f.group[0], f.group[1], labels[0], labels[1], o.next_poses));
      continue;
    }
    AuditEffect e = EffectOf(pb, op, f.terms, fin, f.tau_sigma, ident);
    e.heldout_rms_before = f.rms_before;
    e.heldout_rms_after = f.rms_after;
    e.heldout_loglik_gain = f.ll_gain;
    e.bic_gain = f.bic;
    if (IsWhole(f)) {
      // The whole geometry's gain over the nominal, with the single terms named before it.
      geometry_named = true;
      if (nominal_cv.row_ll.size() == 0) nominal_cv = CrossValidate(pb, nominal, nominal.noise);
      const FitResult g = Refit(TermsOf([&](const Finding& x) { return IsSingle(x); }));
      const FitResult gw = Refit(Union(TermsOf([&](const Finding& x) { return IsSingle(x); }), ident.params));
      const HeldOut gcv = CrossValidate(pb, gw, nominal.noise);
      e.heldout_rms_before = nominal_cv.rms;
      e.heldout_rms_after = gcv.rms;
      e.heldout_loglik_gain = gcv.loglik - nominal_cv.loglik;
      e.bic_gain = BicGain(2.0 * (gw.loglik - nominal.loglik), static_cast<double>(ident.params.size()), logN);
      (void)g;
    }
    rep.effects.push_back(e);
    named.push_back(op.ext);
  }
  // The single geometric terms named before the whole geometry are in it.
  if (geometry_named) {
    std::vector<AuditEffect> kept;
    for (const AuditEffect& e : rep.effects) {
      bool single = false;
      for (const Finding& f : sel.findings)
        if (!f.dropped && !f.undecided && IsSingle(f) && Name(opts[f.option].ext.effect) == e.name &&
            opts[f.option].ext.Where(robot) == e.where)
          single = true;
      if (!single) kept.push_back(e);
    }
    rep.effects = kept;
  } else if (!ident.held.empty()) {
    bool any_geometric = false;
    for (const Finding& f : sel.findings) any_geometric |= !f.dropped && opts[f.option].geometric;
    if (any_geometric) {
      std::string h;
      for (const auto& [name, reason] : ident.held) h += (h.empty() ? "" : ", ") + name;
      rep.notes.push_back("DH parameters not identifiable from these poses with a free registration and tool: " + h);
    }
  }
  for (const auto& label : not_identifiable)
    rep.notes.push_back(label + ": not identifiable from these measurements with a free registration and tool");
  bool failed = false;
  for (const auto& t : rep.tests) failed |= t.failed;
  rep.clean = !failed && rep.effects.empty() && rep.undecided.empty();
  if (failed && rep.effects.empty() && rep.undecided.empty())
    rep.notes.push_back("the nominal model fails a residual test but no effect of the catalog earns its place");

  result.nominal = ToFit(pb, nominal);
  result.extended = ToFit(pb, fin);
  result.extended_robot = ExtendedRobot(pb, fin, &rep.notes, named);

  for (const Finding& f : sel.findings) {
    if (f.dropped || f.undecided || (geometry_named && IsSingle(f))) continue;
    result.plots.push_back(
        EffectPlotOf(pb, log, cov, fin, opts[f.option].key, IsWhole(f) ? ident.params : f.terms, opts[f.option].ext));
  }
}

void RobotAuditRun::OtherSessions() {
  // 5. Other sessions, frozen: the registration only, the whole identifiable geometry, the
  //    final model.
  if (!validate.empty()) {
    say("scoring " + std::to_string(validate.size()) + " other session(s) frozen");
    const FitResult geo = ident.params.empty()
                              ? nominal
                              : FitModel(pb, Union(base_free, ident.params), nominal.theta, nominal.noise);
    // What each named non-geometric cause moves there: the final model refitted without it.
    std::vector<std::pair<std::string, FitResult>> without;
    std::vector<std::pair<std::string, Extension>> without_ext;
    for (const Finding& f : sel.findings)
      if (!f.dropped && !opts[f.option].geometric)
        if (!f.undecided) {
          without.push_back({"final without " + opts[f.option].key,
                             Refit(TermsOf([&](const Finding& x) { return &x != &f && !x.undecided; }))});
          without_ext.push_back({opts[f.option].key, opts[f.option].ext});
        }
    // With tilt sensors (issue 52), the geometry fitted as if the log had none.
    std::optional<FitResult> geo_untilted;
    if (HasTilt(pb) && !ident.params.empty())
      geo_untilted = FitModel(WithoutTilt(pb), Union(base_free, ident.params), nominal.theta, nominal.noise);
    PlacementOptions place;
    place.noise = fin.noise.topLeftCorner(3, 3);
    place.false_alarm = o.false_alarm;
    place.fit_per_station = pb.S > 1;
    for (const RobotLog& v : validate) {
      const Problem pv = MakeProblem(robot, v, o, &pb);
      SessionScore s;
      s.log = v.source.string();
      s.rows = static_cast<int>(v.rows.size());
      s.group_of_row = PostureGroups(log, v);
      if (v.has_stations) {
        // The robot file as given (issue 52: the publisher's baseline): nothing fitted, not
        // even the tool, each station placed from its stationing rows.
        Eigen::VectorXd as_given = nominal.theta;
        as_given.segment(6, pb.ts).setZero();
        s.models.push_back(ScoreModel("nominal", v, PointPredictions(WithoutTilt(pv), as_given), s.group_of_row, place));
        // The same with the tilts its accelerometers measured (issue 52): nothing fitted.
        if (HasTilt(pv))
          s.models.push_back(ScoreModel("nominal + tilt", v, PointPredictions(pv, as_given), s.group_of_row, place));
      }
      // The geometry fitted and scored without the measured tilts: what they move there.
      if (geo_untilted && HasTilt(pv))
        s.models.push_back(ScoreModel("geometry without tilt", v, PointPredictions(WithoutTilt(pv), geo_untilted->theta),
                                      s.group_of_row, place));
      const size_t final_at = s.models.size() + 2;
      for (const auto& [name, fit] : {std::pair<const char*, const FitResult*>{"registration", &nominal},
                                      {"geometry", &geo},
                                      {"final", &fin}})
        s.models.push_back(ScoreModel(name, v, PointPredictions(pv, fit->theta), s.group_of_row, place));
      for (const auto& [name, fit] : without)
        s.models.push_back(ScoreModel(name, v, PointPredictions(pv, fit.theta), s.group_of_row, place));
      for (const auto& e : s.models[final_at].errors) s.scored_rows += !e.empty();
      AddValidationPlots(robot, v, pv, s, without_ext, &result.validation_plots);
      // What remains there: the residual tests on the final model's residuals (as placed).
      {
        FitResult frozen = fin;
        Exact(pv, fin.theta, AllRows(pv), &frozen.R);
        for (int i = 0; i < pv.N; ++i) {
          const Pose& C = s.models[final_at].correction[i];
          if (C.R == Mat3::Identity() && C.t == Vec3::Zero()) continue;
          const Pose T = C * PredictedTool(pv, pv.rows[i], fin.theta);
          frozen.R.row(i).head(3) = (T.t - pv.rows[i].p).transpose();
          if (pv.six) frozen.R.row(i).tail(3) = LogSO3(T.R * pv.rows[i].R.transpose()).transpose();
        }
        AuditReport t;
        int run = 0, nf = 0, shown = 0;
        TestResiduals(v, pv, frozen, Covariates(robot, v, pv), alpha_tests, 0,
                      JitterTolerance(robot, o.repeat_tolerance), &t, &run, &nf);
        std::string failing;
        for (const AuditTest& x : t.tests)
          if (x.failed && ++shown <= 5) {
            char b[200];
            std::snprintf(b, sizeof b, "%s%s (p %.2g)", failing.empty() ? "" : "; ", x.name.c_str(), x.p_value);
            failing += b;
          }
        const std::string where = std::filesystem::path(v.source).filename().string();
        rep.notes.push_back(nf == 0 ? "on " + where + " (frozen), the final model's residuals pass every one of the " +
                                          std::to_string(run) + " residual tests"
                                    : "what remains on " + where + " (frozen): the final model's residuals fail " +
                                          std::to_string(nf) + " of " + std::to_string(run) +
                                          " residual tests: " + failing + (nf > 5 ? "; ..." : ""));
      }
      rep.validation.push_back(s);
    }
  }
}

}  // namespace

RobotAuditResult AuditRobot(const RobotModel& robot, const RobotLog& log, const RobotAuditOptions& o,
                            const std::vector<RobotLog>& validate) {
  std::string why;
  if (!o.IsValid(&why)) Throw("robot audit options: ", why);
  CheckRobotLog(log, robot, kMinRobotMeasurements);
  CheckRobotLogPlausible(log, robot);
  for (const RobotLog& v : validate) {
    CheckRobotLogPlausible(v, robot);
    if (v.NumPoints() != log.NumPoints() || v.six_dof() != log.six_dof())
      Throw(v.source.string(), ": measures ", v.NumPoints(), v.six_dof() ? " point(s) with an orientation" : " point(s)",
            " but the fitted log ", log.source.string(), " measures ", log.NumPoints(),
            log.six_dof() ? " with an orientation" : "", "; a frozen model is scored on the same kind of measurement");
  }
  const int max_folds = std::max(RobotAuditOptions{}.folds, static_cast<int>(log.rows.size()) / 4);
  if (o.folds > max_folds)
    Throw("--folds ", o.folds, ": ", log.source.empty() ? std::string("the robot log") : log.source.string(), " has ",
          log.rows.size(), " measurements, enough for at most ", max_folds,
          " folds of the time-blocked cross-validation (each needs at least 4 measurements)");

  RobotAuditResult result;
  RobotAuditRun run(robot, log, o, validate, &result);
  run.NominalFitAndTests();
  run.Selection();
  run.FinalModel();
  run.Report();
  run.OtherSessions();
  return result;
}

}  // namespace mcms
