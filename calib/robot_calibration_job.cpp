#include "calib/robot_calibration_job.h"

#include <numbers>
#include <chrono>
#include <cstdio>
#include <sstream>

#include "core/error.h"
#include "core/io.h"
#include "core/svg_plot.h"
#include "core/output_folder.h"

namespace mcms {

namespace {
constexpr double kDeg = std::numbers::pi / 180.0;

// A parameter in report units: deg for angles, mm for lengths.
std::string ValueText(const CalibrationParameter& p, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, p.angle ? "%+.5f deg" : "%+.4f mm", p.angle ? v / kDeg : v * 1e3);
  return buf;
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

std::string RunRobotCalibrationJob(const RobotCalibrationJob& job) {
  if (job.output.empty()) Throw("calib-robot: the output robot file is missing; give -o ROBOT.yaml");
  // Refuse outputs that are inputs, and unwritable outputs, before the solve, not after it.
  RequireOutputsSpareInputs({{job.output, "calib-robot -o"},
                             {job.report, "calib-robot --report"},
                             {job.plot, "calib-robot --plot"},
                             {job.plot.empty() ? std::filesystem::path() : JointPlotPath(job.plot), "calib-robot --plot"}},
                            {job.measurements, job.robot});
  RobotModel robot = job.robot.empty() ? RobotModel::Default() : RobotModel::Read(job.robot);
  if (job.tool_guess) robot.SetT_flange_tool(*job.tool_guess);
  RequireWritableFile(job.output, "-o");
  if (!job.report.empty()) RequireWritableFile(job.report, "--report");
  if (!job.plot.empty()) {
    RequireWritableFile(job.plot, "--plot");
    RequireWritableFile(JointPlotPath(job.plot), "--plot");
  }
  const std::vector<RobotMeasurement> ms = ReadRobotMeasurements(job.measurements);
  const auto say = [&](const std::string& line) {
    if (job.progress) job.progress(line);
  };

  RobotCalibrationOptions opt;
  opt.position_sigma_m = job.position_sigma_m;
  opt.rotation_sigma_rad = job.rotation_sigma_rad;
  opt.fixed = job.fixed;
  opt.max_iterations = job.max_iterations;
  opt.estimate_dh = !job.registration_only;
  opt.error_motion_harmonics = job.error_motion_harmonics;
  // The iteration count is not known in advance: a line at most every half second.
  using Clock = std::chrono::steady_clock;
  auto last = Clock::now();
  if (job.progress)
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

  std::optional<CrossValidation> cv;
  if (job.folds >= 2) {
    if (job.folds > static_cast<int>(ms.size()))
      Throw("calib-robot: --folds ", job.folds, " exceeds the ", ms.size(), " measurements; use fewer folds or 0");
    say(std::to_string(job.folds) + "-fold cross-validation");
    RobotCalibrationOptions cv_opt = opt;
    cv_opt.progress = nullptr;
    cv = CrossValidateRobot(robot, guess, ms, cv_opt, job.folds);
  }

  std::ostringstream rep;
  rep << "# mcms calib-robot report\n";
  rep << "robot: " << robot.Name() << " (" << robot.NumJoints() << " joints)\n";
  rep << "measurements: " << ms.size() << " (" << (ms[0].R_meas_tool ? "6-D poses" : "3-D positions") << ") from "
      << job.measurements.string() << "\n";
  rep << "solver: " << (r.converged ? "converged" : "did NOT converge") << " after " << r.iterations
      << " iterations; variance factor " << r.variance_factor << "; observability index " << r.observability << "\n";
  rep << "T_meas_base: " << PoseText(r.T_meas_base) << "\n";
  rep << "T_flange_tool: " << PoseText(r.robot.T_flange_tool()) << "\n";
  rep << "residuals, starting model:            " << ErrorStatsText(Summarize(r.errors_before)) << "\n";
  rep << "residuals, nominal DH registered:     " << ErrorStatsText(Summarize(nominal.errors_after)) << "\n";
  rep << "residuals, calibrated:                " << ErrorStatsText(Summarize(r.errors_after)) << "\n";
  if (cv) {
    rep << "held out (" << job.folds << "-fold), nominal DH: " << ErrorStatsText(Summarize(cv->nominal)) << "\n";
    rep << "held out (" << job.folds << "-fold), calibrated: " << ErrorStatsText(Summarize(cv->calibrated)) << "\n";
  }
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
      pj.x_label = "q" + std::to_string(j + 1) + " (deg)";
      pj.y_label = "position error (mm)";
      for (const PlotSeries& s : plot.series) {
        PlotSeries sj = s;
        for (size_t i = 0; i < sj.x.size() && i < ms.size(); ++i) sj.x[i] = ms[i].q[j] / kDeg;
        pj.series.push_back(sj);
      }
      joints.push_back(pj);
    }
    plot.WriteSvg(job.plot);
    WritePlotGridSvg(JointPlotPath(job.plot), joints, 3);
  }
  r.robot.Write(job.output);
  return report;
}

}  // namespace mcms
