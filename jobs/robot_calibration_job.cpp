#include "jobs/robot_calibration_job.h"

#include <numbers>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>

#include "model/robot_validation.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "model/urdf.h"

namespace mcms {

namespace {
constexpr double kDeg = std::numbers::pi / 180.0;

// A parameter in report units: deg for angles, mm for lengths.
std::string ValueText(const CalibrationParameter& p, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, p.angle ? "%+.5f deg" : "%+.4f mm", p.angle ? v / kDeg : v * 1e3);
  return buf;
}

// Rows x points of a model's predictions on measurements (its errors plus the measured points).
std::vector<std::vector<Vec3>> PredictedRows(const std::vector<PoseError>& e, const std::vector<RobotMeasurement>& m) {
  std::vector<std::vector<Vec3>> rows;
  for (size_t i = 0; i < e.size(); ++i) {
    std::vector<Vec3> r{e[i].dp + m[i].p_meas};
    for (size_t k = 0; k < e[i].other_dp.size(); ++k) r.push_back(e[i].other_dp[k] + m[i].other_points[k]);
    rows.push_back(r);
  }
  return rows;
}

// Per joint of a URDF: its estimated parameters with sigma, for the comment beside its <origin>.
std::map<std::string, std::string> JointComments(const RobotModel& robot, const RobotCalibrationResult& r) {
  std::map<std::string, std::string> c;
  const auto names = GeometryParameterNames(robot);
  const int s = robot.GeometryParamsPerJoint();
  for (int j = 0; j < robot.NumJoints(); ++j) {
    std::ostringstream o;
    o << "mcms calib-robot: corrections folded into this origin (SI, 1 sigma):";
    int listed = 0;
    for (int k = 0; k < s; ++k) {
      const CalibrationParameter& p = r.parameters[s * j + k];
      if (p.fixed) continue;
      char b[160];
      std::snprintf(b, sizeof b, " %s %+.6g +- %.2g %s", names[s * j + k].substr(names[s * j + k].rfind('.') + 1).c_str(),
                    p.estimate, p.sigma, p.angle ? "rad" : "m");
      o << b << ";";
      ++listed;
    }
    if (!listed) o << " none estimated";
    c[robot.Joints()[j].name] = o.str();
  }
  return c;
}
}  // namespace

std::filesystem::path JointPlotPath(const std::filesystem::path& plot) {
  std::filesystem::path p = plot;
  p.replace_filename(plot.stem().string().append("-joints").append(plot.extension().string()));
  return p;
}

std::string PoseText(const Pose& T) {
  const Eigen::Quaterniond q = T.Quaternion();
  std::ostringstream s;
  s.precision(9);
  s << "translation_m [" << T.t.x() << ", " << T.t.y() << ", " << T.t.z() << "], quaternion_wxyz [" << q.w() << ", "
    << q.x() << ", " << q.y() << ", " << q.z() << "]";
  return s.str();
}

std::string ErrorStatsText(const ErrorStats& s) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "position mean %.4f mm, RMS %.4f mm, max %.4f mm", s.mean_position_m * 1e3,
                s.rms_position_m * 1e3, s.max_position_m * 1e3);
  std::string out = buf;
  if (s.mean_rotation_rad) {
    std::snprintf(buf, sizeof buf, "; rotation mean %.5f deg, RMS %.5f deg, max %.5f deg", *s.mean_rotation_rad / kDeg,
                  *s.rms_rotation_rad / kDeg, *s.max_rotation_rad / kDeg);
    out += buf;
  }
  return out;
}

void RunRobotCalibrationJob(const RobotCalibrationJob& job, const JobOutput& out) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  if (job.output.empty()) Throw("calib-robot: the output robot file is missing; give -o ROBOT.yaml (or ROBOT.urdf)");
  // Refuse outputs that are inputs, and unwritable outputs, before the solve, not after it.
  std::vector<std::filesystem::path> inputs{job.measurements, job.robot};
  inputs.insert(inputs.end(), job.validate.begin(), job.validate.end());
  RequireOutputsSpareInputs({{job.output, "calib-robot -o"},
                             {job.report, "calib-robot --report"},
                             {job.json, "calib-robot --json"},
                             {job.plot, "calib-robot --plot"},
                             {job.plot.empty() ? std::filesystem::path() : JointPlotPath(job.plot), "calib-robot --plot"}},
                            inputs);
  if (job.robot.empty() && (!job.chain.base_link.empty() || !job.chain.tip_link.empty()))
    Throw("calib-robot: --base-link and --tip-link pick a chain of a URDF robot; give it with --robot");
  RobotModel robot = job.robot.empty() ? RobotModel::Default() : RobotModel::Read(job.robot, job.chain);
  if (job.tool_guess) robot.SetT_flange_tool(*job.tool_guess);
  RequireWritableFile(job.output, "-o");
  if (!job.report.empty()) RequireWritableFile(job.report, "--report");
  if (!job.json.empty()) RequireWritableFile(job.json, "--json");
  if (!job.plot.empty()) {
    RequireWritableFile(job.plot, "--plot");
    RequireWritableFile(JointPlotPath(job.plot), "--plot");
  }
  std::string out_ext = job.output.extension().string();
  for (auto& c : out_ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (out_ext != ".yaml" && out_ext != ".yml" && out_ext != ".urdf" && out_ext != ".xml")
    Throw("calib-robot -o ", job.output.string(), ": the calibrated robot is written as FILE.yaml or FILE.urdf (or .xml), not '",
          out_ext.empty() ? std::string("(no extension)") : out_ext, "'");
  const bool write_urdf = out_ext == ".urdf" || (robot.Urdf() && out_ext != ".yaml" && out_ext != ".yml");
  const RobotLog log = ReadRobotLog(job.measurements, robot);
  if (static_cast<int>(log.rows.size()) > kMaxAuditRows)
    Throw("calib-robot: ", job.measurements.string(), " has ", log.rows.size(), " measurements, more than the ",
          kMaxAuditRows, " a calibration takes (core/limits.h): thin the log (a few hundred poses identify a robot)");
  if (log.Stations().size() > 1)
    Throw("calib-robot: ", job.measurements.string(), " places the robot at ", log.Stations().size(),
          " stations (a station column); calib-robot fits one placement: fit it with `mcms audit robot`, which "
          "places each station, or give one station's rows");
  const std::vector<RobotMeasurement> ms = KeepPoints(log, job.points, "calib-robot --points").rows;
  std::vector<RobotLog> validate;
  for (const auto& v : job.validate) {
    RobotLog vl = ReadRobotLog(v, robot);
    if (vl.NumPoints() != log.NumPoints() || vl.six_dof() != log.six_dof())
      Throw("calib-robot: --validate ", v.string(), " measures ", vl.NumPoints(), " point(s)",
            vl.six_dof() ? " with an orientation" : "", " but ", job.measurements.string(), " measures ",
            log.NumPoints(), log.six_dof() ? " with an orientation" : "",
            "; a frozen model is scored on the same kind of measurement");
    validate.push_back(std::move(vl));
  }
  std::vector<std::string> reading_notes;
  {
    std::vector<const RobotLog*> logs{&log};
    for (const auto& v : validate) logs.push_back(&v);
    robot = CoverReadings(robot, logs, &reading_notes);
    for (const RobotLog* l : logs) CheckRobotLogPlausible(*l, robot);
  }
  const auto say = [&](const std::string& line) {
    out.Progress(line);
  };

  RobotCalibrationOptions opt;
  opt.position_sigma_m = job.position_sigma_m;
  opt.rotation_sigma_rad = job.rotation_sigma_rad;
  opt.fixed = job.fixed;
  opt.estimate_only = job.estimate_only;
  opt.max_iterations = job.max_iterations;
  opt.estimate_dh = !job.registration_only;
  opt.error_motion_harmonics = job.error_motion_harmonics;
  // The iteration count is not known in advance: a line at most every half second.
  using Clock = std::chrono::steady_clock;
  auto last = Clock::now();
  if (out.progress)
    opt.progress = [&](int iteration, double cost) {
      if (Clock::now() - last < std::chrono::milliseconds(500)) return;
      last = Clock::now();
      std::ostringstream s;
      s << "iteration " << iteration << ", cost " << cost;
      say(s.str());
    };

  const Pose guess = [&] {
    if (job.base_guess) return *job.base_guess;
    try {
      return InitialBaseGuess(robot, ms);
    } catch (const InputError& e) {
      Throw(job.measurements.string(), ": ", e.what());
    }
  }();
  const RobotCalibrationResult r = CalibrateRobot(robot, guess, ms, opt);
  say(std::string(r.converged ? "converged" : "stopped") + " after " + std::to_string(r.iterations) + " iterations");

  // The fair baseline: the nominal DH table with base and tool fitted.
  RobotCalibrationOptions reg = opt;
  reg.estimate_dh = false;
  reg.error_motion_harmonics.clear();
  reg.progress = nullptr;
  const RobotCalibrationResult nominal = CalibrateRobot(robot, guess, ms, reg);

  // Other sessions, frozen: the registered nominal model and the calibrated one.
  std::vector<SessionScore> scores;
  PlacementOptions place;
  {
    // The calibrated model's position noise, for the test of a frozen placement.
    Mat3 S = Mat3::Zero();
    for (const PoseError& e : r.errors_after) S += e.dp * e.dp.transpose();
    place.noise = S / std::max<size_t>(1, r.errors_after.size()) + Mat3::Identity() * 1e-18;
  }
  for (const RobotLog& v : validate) {
    const RobotLog vk = KeepPoints(v, job.points, "calib-robot --points");
    const std::vector<RobotMeasurement>& vm = vk.rows;
    SessionScore sc;
    sc.log = v.source.string();
    sc.rows = static_cast<int>(v.rows.size());
    sc.group_of_row = PostureGroups(log, v);
    sc.models.push_back(
        ScoreModel("registration",
                   vk, PredictedRows(PredictionErrors(nominal.robot, nominal.T_meas_base, vm, nominal.points_tool), vm),
                   sc.group_of_row, place));
    sc.models.push_back(ScoreModel("geometry", vk,
                                   PredictedRows(PredictionErrors(r.robot, r.T_meas_base, vm, r.points_tool), vm),
                                   sc.group_of_row, place));
    for (const auto& e : sc.models.back().errors) sc.scored_rows += !e.empty();
    scores.push_back(sc);
  }

  std::optional<CrossValidation> cv;
  if (job.folds >= 2) {
    if (job.folds > static_cast<int>(ms.size()))
      Throw("calib-robot: --folds ", job.folds, " exceeds the ", ms.size(), " measurements; use fewer folds or 0");
    say(std::to_string(job.folds) + "-fold cross-validation");
    RobotCalibrationOptions cv_opt = opt;
    cv_opt.progress = nullptr;
    cv = CrossValidateRobot(robot, guess, ms, cv_opt, job.folds);
  }

  // Is the solution worth writing? (calib-rig's rule: refused unless --allow-poor-fit.)
  std::vector<std::string> problems;
  {
    double reach = robot.T_flange_tool().t.norm();
    for (const Joint& j : robot.Joints()) reach += std::abs(j.a) + std::abs(j.d) + j.origin.t.norm();
    const ErrorStats after = Summarize(r.errors_after), registered = Summarize(nominal.errors_after);
    const double rms = after.rms_position_m, rms_reg = registered.rms_position_m;
    // What the solver minimises: positions and rotations weighted by their sigmas.
    const auto Cost = [&](const ErrorStats& e) {
      double c = std::pow(e.rms_position_m / job.position_sigma_m, 2);
      if (e.rms_rotation_rad) c += std::pow(*e.rms_rotation_rad / job.rotation_sigma_rad, 2);
      return c;
    };
    char b[320];
    if (!r.converged) {
      std::snprintf(b, sizeof b, "the solver did not converge in %d iterations (--max-iterations)", r.iterations);
      problems.push_back(b);
    }
    if (rms > 0.02 * reach) {
      std::snprintf(b, sizeof b,
                    "the calibrated model misses the measurements by %.4g mm RMS, more than 2 %% of the robot's "
                    "reach (%.3g m): positions in other units than metres, another robot, or a start far from the "
                    "truth (--base-guess, --tool-guess)",
                    rms * 1e3, reach);
      problems.push_back(b);
    }
    if (Cost(after) > 1.0001 * Cost(registered) + 1e-9) {
      std::snprintf(b, sizeof b,
                    "the calibrated model (%.4g mm RMS) fits worse than the nominal model registered (%.4g mm): "
                    "the solver stopped in a wrong minimum (check --tool-guess and --base-guess)",
                    rms * 1e3, rms_reg * 1e3);
      problems.push_back(b);
    }
  }
  std::string list;
  for (const std::string& p : problems) list += "\n  - " + p;
  if (!problems.empty() && !job.allow_poor_fit)
    Throw("calib-robot: the calibration of ", job.measurements.string(), " is not trustworthy:", list,
          "\nno output written (--allow-poor-fit writes it anyway, with this warning)");
  if (!problems.empty())
    out.Progress("WARNING: the calibration is not trustworthy (written because of --allow-poor-fit):" + list);

  std::ostringstream rep;
  rep << "# mcms calib-robot report\n";
  if (!problems.empty())
    rep << "WARNING: the calibration is not trustworthy (written because of --allow-poor-fit):" << list << "\n";
  rep << "robot: " << robot.Name() << " (" << robot.NumJoints() << " joints)\n";
  if (const UrdfSource* u = robot.Urdf())
    rep << "chain: " << u->base_link << " -> " << u->tip_link << " (URDF " << job.robot.string() << ")\n";
  const int K = ms[0].NumPoints();
  rep << "measurements: " << ms.size() << " ("
      << (ms[0].R_meas_tool ? std::string("6-D poses")
                            : K > 1 ? std::to_string(K) + " points of a rigid body" : std::string("3-D positions"))
      << ") from " << job.measurements.string() << "\n";
  if (!log.ignored_columns.empty()) {
    rep << "columns not used:";
    for (const auto& c : log.ignored_columns) rep << " " << c;
    rep << "\n";
  }
  for (const auto& n : reading_notes) rep << "note: " << n << "\n";
  rep << "solver: " << (r.converged ? "converged" : "did NOT converge") << " after " << r.iterations
      << " iterations (whitened cost change over the last 10: " << r.last_cost_change << "); variance factor "
      << r.variance_factor << "; observability index " << r.observability << "\n";
  rep << "T_meas_base: " << PoseText(r.T_meas_base) << "\n";
  rep << "T_flange_tool: " << PoseText(r.robot.T_flange_tool()) << "\n";
  rep << "residuals, starting model:            " << ErrorStatsText(Summarize(r.errors_before)) << "\n";
  rep << "residuals, nominal DH registered:     " << ErrorStatsText(Summarize(nominal.errors_after)) << "\n";
  rep << "residuals, calibrated:                " << ErrorStatsText(Summarize(r.errors_after)) << "\n";
  if (cv) {
    rep << "held out (" << job.folds << "-fold), nominal DH: " << ErrorStatsText(Summarize(cv->nominal)) << "\n";
    rep << "held out (" << job.folds << "-fold), calibrated: " << ErrorStatsText(Summarize(cv->calibrated)) << "\n";
  }
  if (K > 1)
    for (int k = 0; k < K; ++k)
      rep << "point " << k + 1 << ", calibrated: RMS " << SummarizePoint(r.errors_after, k).rms_position_m * 1e3
          << " mm, max " << SummarizePoint(r.errors_after, k).max_position_m * 1e3 << " mm\n";
  rep << ValidationText(scores);
  rep << "parameters (identified error, 1 sigma):\n";
  for (const auto& p : r.parameters) {
    if (p.fixed) continue;
    rep << "  " << p.name << ": " << ValueText(p, p.estimate) << " +- " << ValueText(p, p.sigma).substr(1) << "\n";
  }
  rep << "fixed parameters:\n";
  for (const auto* p : r.Fixed()) rep << "  " << p->name << ": " << p->reason << "\n";
  rep << "correlated pairs (|rho| > " << opt.correlation_threshold << "):" << (r.correlated.empty() ? " none" : "")
      << "\n";
  for (const auto& c : r.correlated) rep << "  " << c.a << " ~ " << c.b << ": rho " << c.rho << "\n";
  const std::string report = rep.str();

  // Everything computed: write the outputs, the robot model last, so that a failed
  // report or plot leaves no model behind (each file is written atomically).
  if (!job.report.empty()) WriteFileAtomically(job.report, [&](std::ostream& o) { o << report; });
  if (!job.json.empty()) {
    nlohmann::json j;
    j["robot"] = robot.Name();
    j["measurements"] = job.measurements.string();
    j["rows"] = ms.size();
    j["points"] = K;
    j["converged"] = r.converged;
    j["variance_factor"] = r.variance_factor;
    const auto Stats = [](const std::vector<PoseError>& e) {
      nlohmann::json a = nlohmann::json::array();
      const int k_max = e.empty() ? 0 : 1 + static_cast<int>(e.front().other_dp.size());
      for (int k = 0; k < k_max; ++k) {
        const ErrorStats st = SummarizePoint(e, k);
        a.push_back({{"point", k + 1}, {"rms_mm", st.rms_position_m * 1e3}, {"max_mm", st.max_position_m * 1e3}});
      }
      return a;
    };
    j["residuals"] = {{"registration", Stats(nominal.errors_after)}, {"geometry", Stats(r.errors_after)}};
    nlohmann::json params = nlohmann::json::array();
    for (const auto& p : r.parameters)
      params.push_back({{"name", p.name},
                        {"estimate", p.estimate},
                        {"sigma", p.sigma},
                        {"fixed", p.fixed},
                        {"unit", p.angle ? "rad" : "m"},
                        {"reason", p.reason}});
    j["parameters"] = params;
    j["validation"] = ValidationJson(scores);
    const std::string text = j.dump(2) + "\n";
    WriteFileAtomically(job.json, [&](std::ostream& o) { o << text; });
  }
  if (!job.plot.empty()) {
    Plot plot;
    plot.title = "Position error per measurement";
    plot.x_label = "measurement";
    plot.y_label = "position error (mm)";
    auto series = [&](const std::string& label, const std::vector<PoseError>& e, const std::string& color) {
      PlotSeries s;
      s.label = label;
      s.color = color;
      s.points = true;
      for (size_t i = 0; i < e.size(); ++i) {
        s.x.push_back(static_cast<double>(i + 1));
        s.y.push_back(e[i].position() * 1e3);
      }
      plot.series.push_back(s);
    };
    series("nominal DH, registered", nominal.errors_after, "#d62728");
    series("calibrated", r.errors_after, "#1f77b4");
    if (cv) series("calibrated, held out", cv->calibrated, "#2ca02c");
    // The same errors against each joint angle, the variable that drives them: a joint offset
    // or error motion shows as a trend or a wave along its own joint.
    std::vector<Plot> joints;
    for (int j = 0; j < robot.NumJoints(); ++j) {
      Plot pj;
      pj.title = "joint " + std::to_string(j + 1);
      const bool rev = robot.Joints()[j].type == JointType::kRevolute;
      pj.x_label = "q" + std::to_string(j + 1) + (rev ? " (deg)" : " (mm)");
      pj.y_label = "position error (mm)";
      for (const PlotSeries& s : plot.series) {
        PlotSeries sj = s;
        for (size_t i = 0; i < sj.x.size() && i < ms.size(); ++i) sj.x[i] = rev ? ms[i].q[j] / kDeg : ms[i].q[j] * 1e3;
        pj.series.push_back(sj);
      }
      joints.push_back(pj);
    }
    plot.WriteSvg(job.plot);
    WritePlotGridSvg(JointPlotPath(job.plot), joints, 3);
  }
  if (write_urdf)
    WriteUrdf(job.output, r.robot, JointComments(robot, r));
  else
    r.robot.Write(job.output);
  out.Print(report);
}

}  // namespace mcms
