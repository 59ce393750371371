#include "fusion/log_fusion.h"
#include "fusion/log_checks.h"

#include <cmath>
#include <cstdio>
#include <numbers>

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"

namespace mcms {

namespace {

std::string Joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ";") + x;
  return s;
}

// A free-text CSV cell: quoted, without commas or quotes inside (core/io.h's reader splits
// at every comma), so that it reads back as one cell.
std::string Quoted(const std::string& text) {
  std::string q = "\"";
  for (const char c : text) q += c == ',' ? ';' : c == '"' ? '\'' : c;
  return q + "\"";
}

// %.17g: a double written and read back is the same double.
std::string Exact(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

void WriteYamlPose(std::ostream& o, const char* name, const Pose& T) {
  const Eigen::Quaterniond q = T.Quaternion();
  o << name << ":\n  translation_m: [" << Exact(T.t.x()) << ", " << Exact(T.t.y()) << ", " << Exact(T.t.z())
    << "]\n  quaternion_wxyz: [" << Exact(q.w()) << ", " << Exact(q.x()) << ", " << Exact(q.y()) << ", " << Exact(q.z())
    << "]\n";
}

}  // namespace

std::vector<FusionWindow> ReadFusionWindows(const std::filesystem::path& path) {
  const CsvTable t = ReadCsv(path);
  const int a = t.Column("start_s"), b = t.Column("end_s");
  if (t.rows.empty()) Throw(path.string(), ": header but no data rows, expected at least one window start_s,end_s");
  std::vector<FusionWindow> w;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    w.push_back({t.Number(i, a), t.Number(i, b)});
    if (!(w.back().end_s > w.back().start_s))
      Throw(path.string(), " line ", t.line_of_row[i], ": end_s ", w.back().end_s, " must exceed start_s ",
            w.back().start_s);
    if (i > 0 && w[i].start_s < w[i - 1].end_s)
      Throw(path.string(), " line ", t.line_of_row[i], ": window starts at ", w[i].start_s,
            " s, before the previous one ends (", w[i - 1].end_s,
            " s); windows must be in time order and must not overlap");
  }
  return w;
}

void WriteFusionWindows(const std::filesystem::path& path, const std::vector<FusionWindow>& windows) {
  CheckWindows(windows);
  WriteFileAtomically(path, [&](std::ostream& o) {
    o << "start_s,end_s\n";
    for (const auto& w : windows) o << Exact(w.start_s) << "," << Exact(w.end_s) << "\n";
  });
}

void WriteJointLog(const std::filesystem::path& path, const JointLog& log, const RobotModel& robot) {
  WriteFileAtomically(path, [&](std::ostream& o) {
    o << "time_s";
    for (int j = 0; j < robot.NumJoints(); ++j)
      o << ",q" << j + 1 << (robot.Joints()[j].type == JointType::kPrismatic ? "_m" : "_rad");
    o << "\n";
    for (const JointSample& s : log.samples) {
      if (s.q.size() != robot.NumJoints())
        Throw("WriteJointLog ", path.string(), ": a sample has ", s.q.size(), " joints, robot '", robot.Name(),
              "' has ", robot.NumJoints());
      o << Exact(s.time_s);
      for (int j = 0; j < s.q.size(); ++j) o << "," << Exact(s.q[j]);
      o << "\n";
    }
  });
}

void WriteInclinometerLog(const std::filesystem::path& path, const InclinometerLog& log) {
  WriteFileAtomically(path, [&](std::ostream& o) {
    o << "time_s,tilt_x_rad,tilt_y_rad\n";
    for (const InclinometerSample& s : log.samples)
      o << Exact(s.time_s) << "," << Exact(s.reading.x()) << "," << Exact(s.reading.y()) << "\n";
  });
}

void WriteFusionSetup(const std::filesystem::path& path, const FusionSetup& setup, const std::string& robot_file) {
  const Mat6& Cb = setup.T_base_rig_covariance;
  Mat6 form = Mat6::Zero();
  form.diagonal() << Cb(0, 0), Cb(0, 0), Cb(0, 0), Cb(3, 3), Cb(3, 3), Cb(3, 3);
  if (Cb != form)
    Throw("WriteFusionSetup ", path.string(),
          ": the setup format holds one rotation and one translation sigma for T_base_rig; its covariance is not "
          "of that form");
  WriteFileAtomically(path, [&](std::ostream& o) {
    o << "# fusion setup (fusion/sensor_logs.h), written by mcms\n";
    if (!robot_file.empty()) o << "robot: " << robot_file << "\n";
    WriteYamlPose(o, "T_base_rig", setup.T_base_rig);
    if (Cb(0, 0) > 0) o << "  sigma_rotation_rad: " << Exact(std::sqrt(Cb(0, 0))) << "\n";
    if (Cb(3, 3) > 0) o << "  sigma_translation_m: " << Exact(std::sqrt(Cb(3, 3))) << "\n";
    WriteYamlPose(o, "T_flange_target", setup.T_flange_target);
    const Inclinometer& in = setup.inclinometer;
    const Eigen::Quaterniond qi(in.R_flange_incl);
    o << "inclinometer:\n  quaternion_wxyz: [" << Exact(qi.w()) << ", " << Exact(qi.x()) << ", " << Exact(qi.y())
      << ", " << Exact(qi.z()) << "]\n  bias_rad: [" << Exact(in.bias.x()) << ", " << Exact(in.bias.y())
      << "]\n  sigma_rad: " << Exact(in.sigma) << "\n  period_s: " << Exact(in.period)
      << "\n  range_rad: " << Exact(in.range) << "\n";
    o << "robot_accuracy:\n  covariance: [";
    for (int i = 0; i < 36; ++i) o << (i ? ", " : "") << Exact(setup.robot_accuracy_covariance(i / 6, i % 6));
    o << "]\n";
    const PoseKalmanOptions& k = setup.kalman;
    o << "kalman:\n  angular_acceleration_psd: " << Exact(k.angular_acceleration_psd)
      << "\n  linear_acceleration_psd: " << Exact(k.linear_acceleration_psd)
      << "\n  initial_angular_velocity_sigma_rad_s: " << Exact(k.initial_angular_velocity_sigma)
      << "\n  initial_linear_velocity_sigma_m_s: " << Exact(k.initial_linear_velocity_sigma)
      << "\n  nis_gate_probability: " << Exact(k.nis_gate_probability) << "\n";
    o << "consistency_significance: " << Exact(setup.consistency_significance) << "\n";
  });
}

namespace {
// Leaves out the readings no sensor of this range can give (|reading - bias| beyond the
// range by more than 5 sigma on either axis), naming each in `dropped`. InputError when
// nothing is left.
void DropOutOfRangeTilts(const Inclinometer& inc, InclinometerLog* log, std::vector<std::string>* dropped) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  const double limit = inc.range + 5.0 * inc.sigma;
  std::vector<InclinometerSample> kept;
  for (const InclinometerSample& s : log->samples) {
    const Vec2 tilt = s.reading - inc.bias;
    const int axis = std::abs(tilt.x()) > limit ? 0 : std::abs(tilt.y()) > limit ? 1 : -1;
    if (axis < 0) {
      kept.push_back(s);
      continue;
    }
    char buf[256];
    std::snprintf(buf, sizeof(buf),
                  "%s line %d: tilt_%c %.4g deg is beyond the inclinometer's range of %.4g deg "
                  "(setup range_deg); reading not used",
                  log->source.string().c_str(), s.line, axis == 0 ? 'x' : 'y', s.reading[axis] / kDeg,
                  inc.range / kDeg);
    dropped->push_back(buf);
  }
  if (kept.empty() && !log->samples.empty())
    Throw(log->source.string(), ": every inclinometer reading is beyond the sensor's range of ", inc.range / kDeg,
          " deg (setup file inclinometer.range_deg); check the units of the log and the setup");
  log->samples = std::move(kept);
}
}  // namespace

FuseFilesResult FuseLogFiles(const FuseFilesRequest& r) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  FuseFilesResult out;
  out.setup = ReadFusionSetup(r.setup);  // (and the robot file it names: an input too)
  RequireOutputsSpareInputs({{r.output, "fuse -o"}}, {r.tracker, r.robot, r.inclinometer, r.setup, r.windows});
  out.logs.tracker = ReadTrackerLog(r.tracker);
  if (!r.robot.empty()) out.logs.robot = ReadJointLog(r.robot, out.setup.robot);
  if (!r.inclinometer.empty()) {
    out.logs.inclinometer = ReadInclinometerLog(r.inclinometer);
    DropOutOfRangeTilts(out.setup.inclinometer, &*out.logs.inclinometer, &out.dropped);
  }
  if (!r.windows.empty()) out.windows = ReadFusionWindows(r.windows);
  CheckTimeOverlap(out.logs);
  if (out.logs.robot) CheckTrackerAgainstJoints(out.setup, out.logs.tracker, *out.logs.robot);
  if (out.logs.inclinometer) CheckInclinometerAgainstTracker(out.setup, out.logs.tracker, *out.logs.inclinometer);
  StreamFusionOptions so;
  so.moifa = r.moifa;
  so.kalman = r.kalman;
  so.windows = out.windows;
  try {
    out.rows = FuseStream(out.logs, out.setup, so);
  } catch (const InputError& e) {
    // The windows' own errors name the file they came from.
    if (!r.windows.empty() && std::string(e.what()).rfind("fusion window", 0) == 0)
      Throw(r.windows.string(), ": ", e.what());
    throw;
  }
  if (!r.output.empty()) WriteFusedPoseCsv(r.output, out.rows);
  return out;
}

void WriteFusedPoseCsv(const std::filesystem::path& path, const std::vector<FusedSample>& samples) {
  static const char* kAxes[6] = {"rx", "ry", "rz", "px", "py", "pz"};
  WriteFileAtomically(path, [&](std::ostream& o) {
    o << "frame,time_s,method,x_m,y_m,z_m,qw,qx,qy,qz,sensors,dof,p_value,flagged,excluded,fault";
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) o << ",cov_" << kAxes[r] << "_" << kAxes[c];
    o << "\n";
    char buf[64];
    const auto num = [&](double v) {
      std::snprintf(buf, sizeof buf, "%.12g", v);
      return std::string(buf);
    };
    for (const FusedSample& s : samples) {
      const auto q = s.T_base_flange.Quaternion();
      const Vec3& t = s.T_base_flange.t;
      o << s.frame << "," << CsvTime(s.time_s, 12) << "," << ToString(s.method) << "," << num(t.x()) << "," << num(t.y()) << ","
        << num(t.z()) << "," << num(q.w()) << "," << num(q.x()) << "," << num(q.y()) << "," << num(q.z()) << ","
        << Joined(s.sensors) << "," << s.dof << "," << num(s.p_value) << "," << Joined(s.flagged) << ","
        << Joined(s.excluded) << "," << Quoted(s.fault);
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) o << "," << num(s.covariance(r, c));
      o << "\n";
    }
  });
}

}  // namespace mcms
