// Python bindings: robot models (FK, Jacobian, pose covariance, IK), robot calibration,
// ISO 9283 characteristics, and the sensor fusion (MOIFA and Kalman) of tracker, joint and
// inclinometer streams.
#include <cmath>

#include "calib/iso9283.h"
#include "audit/robot_audit.h"
#include "calib/robot_calibration.h"
#include "fusion/sensor_logs.h"
#include "fusion/stream_fusion.h"
#include "model/inverse_kinematics.h"
#include "model/robot_model.h"
#include "python/py_common.h"

namespace mcms::python {

namespace {

RobotModel::EndFrame GetEnd(const std::string& end) {
  if (end == "tool") return RobotModel::EndFrame::kTool;
  if (end == "flange") return RobotModel::EndFrame::kFlange;
  Throw("argument 'end': expected 'tool' or 'flange', got '", end, "'");
}

Eigen::VectorXd GetJoints(const RobotModel& r, py::handle q, const std::string& name = "q") {
  return GetVector(q, name, r.NumJoints());
}

// (M, n) joint values, (M, 3) positions, optional (M, 3, 3) rotations -> measurements.
std::vector<RobotMeasurement> GetMeasurements(const RobotModel& robot, py::handle q, py::handle p_meas,
                                              py::handle R_meas) {
  Numbers Q = GetNumbers(q, "q", {{-1, robot.NumJoints()}});
  const py::ssize_t m = Q.dim(0);
  Numbers P = GetNumbers(p_meas, "p_meas", {{m, 3}});
  std::optional<Numbers> R;
  if (!R_meas.is_none()) R = GetNumbers(R_meas, "R_meas", {{m, 3, 3}});
  std::vector<RobotMeasurement> out(static_cast<size_t>(m));
  const int n = robot.NumJoints();
  for (py::ssize_t i = 0; i < m; ++i) {
    auto& x = out[static_cast<size_t>(i)];
    x.q = Eigen::Map<const Eigen::VectorXd>(Q.data() + n * i, n);
    x.p_meas = Eigen::Map<const Vec3>(P.data() + 3 * i);
    x.source = "row " + std::to_string(i) + " of the arrays";
    if (R) {
      Mat3 Ri = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(R->data() + 9 * i);
      if ((Ri.transpose() * Ri - Mat3::Identity()).norm() > 1e-6 || Ri.determinant() < 0)
        Throw("argument 'R_meas'[", i, "]: not a rotation matrix");
      x.R_meas_tool = Eigen::Quaterniond(Ri).normalized().toRotationMatrix();
    }
    std::string why;
    if (!robot.WithinLimits(x.q, &why)) Throw("argument 'q' row ", i, ": ", why);
  }
  return out;
}

py::dict ErrorsDict(const std::vector<PoseError>& e) {
  std::vector<Vec3> dp;
  std::vector<double> rot;
  bool has_rot = !e.empty() && e.front().rotation_rad.has_value();
  for (const auto& x : e) {
    dp.push_back(x.dp);
    rot.push_back(x.rotation_rad.value_or(std::nan("")));
  }
  const ErrorStats s = Summarize(e);
  py::dict d;
  d["dp"] = Vec3sToArray(dp);
  d["rotation_rad"] = has_rot ? py::object(Array({static_cast<py::ssize_t>(rot.size())}, rot.data())) : py::none();
  d["rms_position_m"] = s.rms_position_m;
  d["mean_position_m"] = s.mean_position_m;
  d["max_position_m"] = s.max_position_m;
  d["rms_rotation_rad"] = s.rms_rotation_rad ? py::object(py::float_(*s.rms_rotation_rad)) : py::none();
  return d;
}

RobotCalibrationOptions GetCalibrationOptions(const py::kwargs& kw) {
  RobotCalibrationOptions o;
  for (auto item : kw) {
    const std::string key = py::str(item.first);
    auto num = [&]() { return GetNumbers(item.second, key, {std::vector<py::ssize_t>{}}).values[0]; };
    if (key == "position_sigma_m")
      o.position_sigma_m = num();
    else if (key == "rotation_sigma_rad")
      o.rotation_sigma_rad = num();
    else if (key == "estimate_dh")
      o.estimate_dh = item.second.cast<bool>();
    else if (key == "estimate_base")
      o.estimate_base = item.second.cast<bool>();
    else if (key == "estimate_tool")
      o.estimate_tool = item.second.cast<bool>();
    else if (key == "fixed")
      o.fixed = item.second.cast<std::vector<std::string>>();
    else if (key == "error_motion_harmonics")
      o.error_motion_harmonics = item.second.cast<std::vector<int>>();
    else if (key == "require_pose_identifiability")
      o.require_pose_identifiability = item.second.cast<bool>();
    else if (key == "scale_covariance")
      o.scale_covariance = item.second.cast<bool>();
    else if (key == "max_iterations")
      o.max_iterations = item.second.cast<int>();
    else if (key == "correlation_threshold")
      o.correlation_threshold = num();
    else
      Throw("unknown calibration option '", key,
            "'; expected position_sigma_m, rotation_sigma_rad, estimate_dh, estimate_base, estimate_tool, fixed, "
            "error_motion_harmonics, require_pose_identifiability, scale_covariance, max_iterations, "
            "correlation_threshold");
  }
  std::string why;
  if (!o.IsValid(&why)) Throw("calibration options: ", why);
  return o;
}

// Times (N,) strictly increasing and finite; `what` names the argument.
std::vector<double> GetTimes(py::handle h, const std::string& what, py::ssize_t n = -1) {
  Numbers t = GetNumbers(h, what, {{n}});
  for (size_t i = 1; i < t.values.size(); ++i)
    if (!(t.values[i] > t.values[i - 1]))
      Throw("argument '", what, "': time stamps must strictly increase (element ", i, " is ", t.values[i],
            " after ", t.values[i - 1], ")");
  return t.values;
}

py::handle Item(const py::dict& d, const char* key, const std::string& arg) {
  if (!d.contains(key)) Throw("argument '", arg, "': missing key '", key, "'");
  return d[key];
}

TrackerLog GetTrackerLog(py::handle h) {
  if (py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"))
    return ReadTrackerLog(py::str(h).cast<std::string>());
  if (!py::isinstance<py::dict>(h))
    Throw("argument 'tracker': expected a path to the tracker's pose CSV or a dict with time_s (N,), T_rig_target "
          "(N, 4, 4), cov (N, 6, 6)");
  py::dict d = py::reinterpret_borrow<py::dict>(h);
  TrackerLog log;
  log.source = "argument 'tracker'";
  const auto t = GetTimes(Item(d, "time_s", "tracker"), "tracker['time_s']");
  const auto T = GetPoses(Item(d, "T_rig_target", "tracker"), "tracker['T_rig_target']");
  const py::ssize_t n = static_cast<py::ssize_t>(t.size());
  Numbers C = GetNumbers(Item(d, "cov", "tracker"), "tracker['cov']", {{n, 6, 6}});
  if (static_cast<py::ssize_t>(T.size()) != n)
    Throw("argument 'tracker': time_s has ", n, " rows, T_rig_target ", T.size());
  if (n == 0) Throw("argument 'tracker': no samples");
  std::optional<Numbers> frames;
  if (d.contains("frame")) frames = GetNumbers(d["frame"], "tracker['frame']", {{n}});
  for (py::ssize_t i = 0; i < n; ++i) {
    TrackerSample s;
    s.frame = frames ? static_cast<int>(frames->values[i]) : static_cast<int>(i);
    s.time_s = t[i];
    s.line = static_cast<int>(i);
    s.T_rig_target = T[i];
    s.covariance = Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(C.data() + 36 * i);
    if ((s.covariance - s.covariance.transpose()).cwiseAbs().maxCoeff() > 1e-9 * s.covariance.cwiseAbs().maxCoeff() ||
        Eigen::LLT<Mat6>(s.covariance).info() != Eigen::Success)
      Throw("argument 'tracker['cov']'[", i, "]: expected a symmetric positive-definite 6x6 covariance");
    log.samples.push_back(s);
  }
  log.first_time_s = t.front();
  log.last_time_s = t.back();
  return log;
}

std::optional<JointLog> GetJointLog(py::handle h, const RobotModel& robot) {
  if (h.is_none()) return std::nullopt;
  if (py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"))
    return ReadJointLog(py::str(h).cast<std::string>(), robot);
  if (!py::isinstance<py::dict>(h))
    Throw("argument 'robot': expected a path to the joint log CSV or a dict with time_s (M,), q (M, n) in rad/m");
  py::dict d = py::reinterpret_borrow<py::dict>(h);
  JointLog log;
  log.source = "argument 'robot'";
  const auto t = GetTimes(Item(d, "time_s", "robot"), "robot['time_s']");
  const py::ssize_t n = static_cast<py::ssize_t>(t.size());
  Numbers Q = GetNumbers(Item(d, "q", "robot"), "robot['q']", {{n, robot.NumJoints()}});
  for (py::ssize_t i = 0; i < n; ++i) {
    JointSample s;
    s.time_s = t[i];
    s.line = static_cast<int>(i);
    s.q = Eigen::Map<const Eigen::VectorXd>(Q.data() + robot.NumJoints() * i, robot.NumJoints());
    std::string why;
    if (!robot.WithinLimits(s.q, &why)) Throw("argument 'robot['q']' row ", i, ": ", why);
    log.samples.push_back(s);
  }
  if (log.samples.empty()) Throw("argument 'robot': no samples");
  return log;
}

std::optional<InclinometerLog> GetInclinometerLog(py::handle h) {
  if (h.is_none()) return std::nullopt;
  if (py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"))
    return ReadInclinometerLog(py::str(h).cast<std::string>());
  if (!py::isinstance<py::dict>(h))
    Throw("argument 'inclinometer': expected a path to the inclinometer CSV or a dict with time_s (K,), "
          "reading_rad (K, 2)");
  py::dict d = py::reinterpret_borrow<py::dict>(h);
  InclinometerLog log;
  log.source = "argument 'inclinometer'";
  const auto t = GetTimes(Item(d, "time_s", "inclinometer"), "inclinometer['time_s']");
  const py::ssize_t n = static_cast<py::ssize_t>(t.size());
  Numbers R = GetNumbers(Item(d, "reading_rad", "inclinometer"), "inclinometer['reading_rad']", {{n, 2}});
  for (py::ssize_t i = 0; i < n; ++i)
    log.samples.push_back({t[i], static_cast<int>(i), Vec2(R.values[2 * i], R.values[2 * i + 1])});
  if (log.samples.empty()) Throw("argument 'inclinometer': no samples");
  return log;
}

py::dict Iso(const PoseCharacteristics& c) {
  py::dict d;
  d["n"] = c.n;
  d["barycentre"] = Array({3}, c.barycentre.data());
  d["AP_p"] = c.AP_p;
  d["AP_xyz"] = Array({3}, c.AP_xyz.data());
  d["AP_a"] = c.AP_a, d["AP_b"] = c.AP_b, d["AP_c"] = c.AP_c;
  d["l_bar"] = c.l_bar, d["S_l"] = c.S_l, d["RP_l"] = c.RP_l;
  d["RP_a"] = c.RP_a, d["RP_b"] = c.RP_b, d["RP_c"] = c.RP_c;
  return d;
}

}  // namespace

namespace {

void BindRobotModel(py::module_& m) {
  py::class_<RobotModel>(m, "RobotModel", "A serial robot (DH parameters): FK, Jacobian, pose covariance, IK.")
      .def_static("default", &RobotModel::Default, "The KUKA KR 5 arc of the paper (embedded).")
      .def_static(
          "read", [](const std::string& path) { return RobotModel::Read(path); }, py::arg("path"))
      .def_static(
          "parse", [](const std::string& text, const std::string& source) { return RobotModel::Parse(text, source); },
          py::arg("yaml_text"), py::arg("source") = "<string>")
      .def(
          "write", [](const RobotModel& r, const std::string& path) { r.Write(path); }, py::arg("path"))
      .def("to_yaml", &RobotModel::ToYaml)
      .def(py::pickle([](const RobotModel& r) { return r.ToYaml(); },
                      [](const std::string& yaml) { return RobotModel::Parse(yaml, "<pickle>"); }))
      .def_property_readonly("name", &RobotModel::Name)
      .def_property_readonly("num_joints", &RobotModel::NumJoints)
      .def_property_readonly("joint_names",
                             [](const RobotModel& r) {
                               std::vector<std::string> n;
                               for (const auto& j : r.Joints()) n.push_back(j.name);
                               return n;
                             })
      .def_property_readonly("lower",
                             [](const RobotModel& r) {
                               Eigen::VectorXd v(r.NumJoints());
                               for (int i = 0; i < r.NumJoints(); ++i) v[i] = r.Joints()[i].lower;
                               return v;
                             })
      .def_property_readonly("upper",
                             [](const RobotModel& r) {
                               Eigen::VectorXd v(r.NumJoints());
                               for (int i = 0; i < r.NumJoints(); ++i) v[i] = r.Joints()[i].upper;
                               return v;
                             })
      .def_property_readonly("encoder_sigma",
                             [](const RobotModel& r) {
                               Eigen::VectorXd v(r.NumJoints());
                               for (int i = 0; i < r.NumJoints(); ++i) v[i] = r.Joints()[i].encoder_sigma;
                               return v;
                             })
      .def_property_readonly("dh",
                             [](const RobotModel& r) {
                               Eigen::MatrixXd v(r.NumJoints(), 4);
                               for (int i = 0; i < r.NumJoints(); ++i) {
                                 const Joint& j = r.Joints()[i];
                                 v.row(i) << j.theta_offset, j.d, j.a, j.alpha;
                               }
                               return v;
                             },
                             "(n, 4): theta_offset, d, a, alpha per joint (rad, m).")
      .def_property(
          "T_flange_tool", [](const RobotModel& r) { return PoseToArray(r.T_flange_tool()); },
          [](RobotModel& r, py::handle T) { r.SetT_flange_tool(GetPose(T, "T_flange_tool")); })
      .def(
          "check_joints", [](const RobotModel& r, py::handle q) { r.CheckJoints(GetJoints(r, q)); }, py::arg("q"),
          "InputError naming the joint when q is outside the limits.")
      .def(
          "T_base_flange", [](const RobotModel& r, py::handle q) { return PoseToArray(r.T_base_flange(GetJoints(r, q))); },
          py::arg("q"), "Forward kinematics (4x4).")
      .def(
          "T_base_tool", [](const RobotModel& r, py::handle q) { return PoseToArray(r.T_base_tool(GetJoints(r, q))); },
          py::arg("q"))
      .def(
          "link_frames", [](const RobotModel& r, py::handle q) { return PosesToArray(r.LinkFrames(GetJoints(r, q))); },
          py::arg("q"), "(n+1, 4, 4) link frames T_base_link_i, base first, flange last.")
      .def(
          "jacobian",
          [](const RobotModel& r, py::handle q, const std::string& end) {
            return Eigen::MatrixXd(r.Jacobian(GetJoints(r, q), GetEnd(end)));
          },
          py::arg("q"), py::arg("end") = "tool", "6 x n geometric Jacobian in the [dtheta; dp] layout, base frame.")
      .def(
          "pose_covariance",
          [](const RobotModel& r, py::handle q, py::handle Q, const std::string& end) {
            const Eigen::VectorXd qv = GetJoints(r, q);
            if (Q.is_none()) return Mat6(r.PoseCovariance(qv, GetEnd(end)));
            return Mat6(r.PoseCovariance(qv, GetMatrix(Q, "Q", r.NumJoints(), r.NumJoints()), GetEnd(end)));
          },
          py::arg("q"), py::arg("Q") = py::none(), py::arg("end") = "tool",
          "J Q J^T (6x6, [dtheta; dp]); Q defaults to the encoder covariance.")
      .def(
          "solve_ik",
          [](const RobotModel& r, py::handle T_goal, py::handle seed, int max_iterations, double tolerance) {
            IkOptions o;
            o.max_iterations = max_iterations;
            o.tolerance = tolerance;
            std::string why;
            const Pose goal = GetPose(T_goal, "T_base_flange_goal");
            const Eigen::VectorXd s = GetJoints(r, seed, "seed");
            auto q = SolveIk(r, goal, s, &why, o);
            if (!q) throw std::runtime_error("no IK solution within the joint limits: " + why);
            return Eigen::VectorXd(*q);
          },
          py::arg("T_base_flange_goal"), py::arg("seed"), py::arg("max_iterations") = 200,
          py::arg("tolerance") = 1e-9,
          "Joint values reaching the flange goal from the seed (damped least squares within the limits); "
          "RuntimeError with the reason when it does not converge.")
      .def("__repr__", [](const RobotModel& r) {
        return "<mcms.RobotModel " + r.Name() + ", " + std::to_string(r.NumJoints()) + " joints>";
      });

}

void BindRobotCalibration(py::module_& m) {
  m.def(
      "read_robot_measurements",
      [](const std::string& path) {
        const auto ms = ReadRobotMeasurements(path);
        if (ms.empty()) Throw(path, ": no measurements");
        const py::ssize_t n = static_cast<py::ssize_t>(ms.size()), nj = ms.front().q.size();
        std::vector<double> q, p, R;
        const bool six = ms.front().R_meas_tool.has_value();
        for (const auto& x : ms) {
          if (x.q.size() != nj) Throw(path, ": ", x.source, " has ", x.q.size(), " joints, the first has ", nj);
          q.insert(q.end(), x.q.data(), x.q.data() + nj);
          p.insert(p.end(), x.p_meas.data(), x.p_meas.data() + 3);
          if (six) {
            Eigen::Matrix<double, 3, 3, Eigen::RowMajor> Rr = x.R_meas_tool.value_or(Mat3::Identity());
            R.insert(R.end(), Rr.data(), Rr.data() + 9);
          }
        }
        py::dict d;
        d["q"] = Array({n, nj}, q.data());
        d["p_meas"] = Array({n, 3}, p.data());
        d["R_meas"] = six ? py::object(Array({n, 3, 3}, R.data())) : py::none();
        return d;
      },
      py::arg("path"), "Robot measurements (YAML) as arrays: q (M, n), p_meas (M, 3), R_meas (M, 3, 3) or None.");

  m.def(
      "initial_base_guess",
      [](const RobotModel& robot, py::handle q, py::handle p_meas) {
        return PoseToArray(InitialBaseGuess(robot, GetMeasurements(robot, q, p_meas, py::none())));
      },
      py::arg("robot"), py::arg("q"), py::arg("p_meas"), "Umeyama/Kabsch T_meas_base from nominal tool positions.");

  m.def(
      "prediction_errors",
      [](const RobotModel& robot, py::handle T_meas_base, py::handle q, py::handle p_meas, py::handle R_meas) {
        return ErrorsDict(PredictionErrors(robot, GetPose(T_meas_base, "T_meas_base"),
                                           GetMeasurements(robot, q, p_meas, R_meas)));
      },
      py::arg("robot"), py::arg("T_meas_base"), py::arg("q"), py::arg("p_meas"), py::arg("R_meas") = py::none());

  m.def(
      "calibrate_robot",
      [](const RobotModel& robot, py::handle q, py::handle p_meas, py::handle R_meas, py::handle T_meas_base_guess,
         py::kwargs kw) {
        const auto ms = GetMeasurements(robot, q, p_meas, R_meas);
        const RobotCalibrationOptions o = GetCalibrationOptions(kw);
        const Pose guess =
            T_meas_base_guess.is_none() ? InitialBaseGuess(robot, ms) : GetPose(T_meas_base_guess, "T_meas_base_guess");
        RobotCalibrationResult r;
        {
          py::gil_scoped_release release;
          r = CalibrateRobot(robot, guess, ms, o);
        }
        py::dict d;
        d["robot"] = r.robot;
        d["T_meas_base"] = PoseToArray(r.T_meas_base);
        py::list params;
        for (const auto& p : r.parameters) {
          py::dict e;
          e["name"] = p.name;
          e["initial"] = p.initial;
          e["estimate"] = p.estimate;
          e["sigma"] = p.sigma;
          e["fixed"] = p.fixed;
          e["unit"] = p.angle ? "rad" : "m";
          e["reason"] = p.reason;
          params.append(e);
        }
        d["parameters"] = params;
        d["covariance"] = r.covariance;
        d["free_parameters"] = r.free_parameters;
        py::list corr;
        for (const auto& c : r.correlated) corr.append(py::make_tuple(c.a, c.b, c.rho));
        d["correlated"] = corr;
        d["errors_before"] = ErrorsDict(r.errors_before);
        d["errors_after"] = ErrorsDict(r.errors_after);
        d["variance_factor"] = r.variance_factor;
        d["observability"] = r.observability;
        d["iterations"] = r.iterations;
        d["converged"] = r.converged;
        return d;
      },
      py::arg("robot"), py::arg("q"), py::arg("p_meas"), py::arg("R_meas") = py::none(),
      py::arg("T_meas_base_guess") = py::none(),
      "Kinematic calibration (calib/robot_calibration.h) from joint values q (M, n) and measured tool positions "
      "p_meas (M, 3) (and orientations R_meas (M, 3, 3) for 6-D). Options as keywords (position_sigma_m, "
      "rotation_sigma_rad, estimate_dh, estimate_base, estimate_tool, fixed, error_motion_harmonics, ...). Returns "
      "a dict: robot (calibrated RobotModel), T_meas_base, parameters, covariance, errors_before/after, ...");

  m.def(
      "cross_validate_robot",
      [](const RobotModel& robot, py::handle q, py::handle p_meas, py::handle R_meas, py::handle T_meas_base_guess,
         int folds, py::kwargs kw) {
        const auto ms = GetMeasurements(robot, q, p_meas, R_meas);
        const RobotCalibrationOptions o = GetCalibrationOptions(kw);
        if (folds < 2 || folds > static_cast<int>(ms.size()))
          Throw("argument 'folds': expected 2..", ms.size(), ", got ", folds);
        const Pose guess =
            T_meas_base_guess.is_none() ? InitialBaseGuess(robot, ms) : GetPose(T_meas_base_guess, "T_meas_base_guess");
        CrossValidation cv;
        {
          py::gil_scoped_release release;
          cv = CrossValidateRobot(robot, guess, ms, o, folds);
        }
        py::dict d;
        d["calibrated"] = ErrorsDict(cv.calibrated);
        d["nominal"] = ErrorsDict(cv.nominal);
        return d;
      },
      py::arg("robot"), py::arg("q"), py::arg("p_meas"), py::arg("R_meas") = py::none(),
      py::arg("T_meas_base_guess") = py::none(), py::arg("folds") = 5,
      "k-fold held-out prediction errors of the calibrated model and of the nominal model registered on the same "
      "folds (measurement i in fold i mod k). Options as calibrate_robot's.");

  m.def(
      "audit_robot",
      [](const std::string& log, std::optional<RobotModel> robot, const std::vector<std::string>& only,
         double false_alarm, int folds, int max_effects) {
        const RobotModel model = robot ? *robot : RobotModel::Default();
        RobotAuditOptions o;
        o.only = only;
        o.false_alarm = false_alarm;
        o.folds = folds;
        o.max_effects = max_effects;
        std::string why;
        if (!o.IsValid(&why)) Throw("audit_robot: ", why);
        RobotAuditResult r;
        {
          py::gil_scoped_release release;
          r = AuditRobot(model, ReadRobotLog(log, model), o);
        }
        // The report's JSON (the CLI's --json) as Python objects, plus the text and the
        // robot with the effects its description can hold.
        py::dict d = py::module_::import("json").attr("loads")(r.report.ToJson());
        d["text"] = r.report.Text();
        d["extended_robot"] = r.extended_robot;
        return d;
      },
      py::arg("log"), py::arg("robot") = py::none(), py::arg("only") = std::vector<std::string>{},
      py::arg("false_alarm") = 0.01, py::arg("folds") = 5, py::arg("max_effects") = 4,
      "The robot mode of the model audit (`mcms audit robot`): the report as the --json file's dict "
      "('mode', 'nominal', 'clean', 'effects', 'undecided'), with 'text' and 'extended_robot'.");

  m.def(
      "iso9283_pose",
      [](py::handle commanded, py::handle attained) {
        return Iso(PoseAccuracyRepeatability(GetPose(commanded, "commanded"), GetPoses(attained, "attained")));
      },
      py::arg("commanded"), py::arg("attained"),
      "ISO 9283 7.2 pose accuracy and repeatability (AP, RP) of (n, 4, 4) attained poses of one commanded pose.");
  m.def(
      "iso9283_distance",
      [](py::handle c1, py::handle c2, py::handle a1, py::handle a2) {
        const auto r = DistanceAccuracyRepeatability(GetPose(c1, "commanded1"), GetPose(c2, "commanded2"),
                                                     GetPoses(a1, "attained1"), GetPoses(a2, "attained2"));
        py::dict d;
        d["n"] = r.n;
        d["D_c"] = r.D_c, d["D_bar"] = r.D_bar, d["AD_p"] = r.AD_p, d["S_D"] = r.S_D, d["RD_p"] = r.RD_p;
        d["AD_xyz"] = Array({3}, r.AD_xyz.data());
        d["RD_xyz"] = Array({3}, r.RD_xyz.data());
        return d;
      },
      py::arg("commanded1"), py::arg("commanded2"), py::arg("attained1"), py::arg("attained2"),
      "ISO 9283 7.5 distance accuracy and repeatability (AD, RD).");
}

void BindFusion(py::module_& m) {
  m.def(
      "iso9283_path",
      [](py::handle commanded, py::handle attained) {
        const auto c = GetPoints3(commanded, "commanded");
        if (!py::isinstance<py::sequence>(attained))
          Throw("argument 'attained': expected a list of (K, 3) polylines, one per run");
        std::vector<std::vector<Vec3>> runs;
        py::sequence s = py::reinterpret_borrow<py::sequence>(attained);
        for (size_t i = 0; i < s.size(); ++i) runs.push_back(GetPoints3(s[i], "attained[" + std::to_string(i) + "]"));
        const auto r = PathAccuracyRepeatability(c, runs);
        py::dict d;
        d["AT_p"] = r.AT_p, d["RT_p"] = r.RT_p;
        d["AT_i"] = r.AT_i, d["RT_i"] = r.RT_i;
        d["barycentres"] = Vec3sToArray(r.barycentres);
        return d;
      },
      py::arg("commanded"), py::arg("attained"), "ISO 9283 8.2 path accuracy and repeatability (AT, RT).");

  py::class_<FusionSetup>(m, "FusionSetup", "The cell geometry and sensor models of the fusion (fusion/sensor_logs.h).")
      .def_static(
          "read", [](const std::string& path) { return ReadFusionSetup(path); }, py::arg("path"))
      .def_static(
          "parse",
          [](const std::string& text, const std::string& base_dir) {
            return ParseFusionSetup(text, "<string>", base_dir);
          },
          py::arg("yaml_text"), py::arg("base_dir") = ".")
      .def_readonly("robot", &FusionSetup::robot)
      .def_property_readonly("T_base_rig", [](const FusionSetup& s) { return PoseToArray(s.T_base_rig); })
      .def_property_readonly("T_flange_target", [](const FusionSetup& s) { return PoseToArray(s.T_flange_target); })
      .def_readwrite("consistency_significance", &FusionSetup::consistency_significance)
      .def_readwrite("exclude_faults", &FusionSetup::exclude_faults);

  m.def(
      "camera_flange_pose",
      [](const FusionSetup& setup, py::handle T_rig_target, py::handle cov) {
        const auto r = CameraFlangePose(GetPose(T_rig_target, "T_rig_target"), GetCovariance(cov, "cov", 6), setup);
        return py::make_tuple(PoseToArray(r.T), Mat6(r.covariance));
      },
      py::arg("setup"), py::arg("T_rig_target"), py::arg("cov"),
      "The camera's measurement (T_base_flange, 6x6 covariance) of one tracked pose in the setup's cell.");
  m.def(
      "robot_flange_pose",
      [](const FusionSetup& setup, py::handle q) {
        const auto r = RobotFlangePose(GetVector(q, "q", setup.robot.NumJoints()), setup);
        return py::make_tuple(PoseToArray(r.T), Mat6(r.covariance));
      },
      py::arg("setup"), py::arg("q"),
      "The robot's measurement (T_base_flange by FK, encoder plus accuracy covariance) at joint values q.");

  m.def(
      "fuse",
      [](py::handle setup_arg, py::handle tracker, py::handle robot, py::handle inclinometer, bool moifa, bool kalman,
         py::handle windows) {
        FusionSetup setup;
        if (py::isinstance<FusionSetup>(setup_arg))
          setup = setup_arg.cast<FusionSetup>();
        else if (py::isinstance<py::str>(setup_arg) || py::hasattr(setup_arg, "__fspath__"))
          setup = ReadFusionSetup(py::str(setup_arg).cast<std::string>());
        else
          Throw("argument 'setup': expected a FusionSetup or the path of a setup YAML");
        SensorLogs logs;
        logs.tracker = GetTrackerLog(tracker);
        logs.robot = GetJointLog(robot, setup.robot);
        logs.inclinometer = GetInclinometerLog(inclinometer);
        StreamFusionOptions o;
        o.moifa = moifa;
        o.kalman = kalman;
        if (!moifa && !kalman) Throw("arguments 'moifa', 'kalman': at least one method must be on");
        if (!windows.is_none()) {
          Numbers w = GetNumbers(windows, "windows", {{-1, 2}});
          for (py::ssize_t i = 0; i < w.dim(0); ++i) o.windows.push_back({w.values[2 * i], w.values[2 * i + 1]});
        }
        std::vector<FusedSample> r;
        {
          py::gil_scoped_release release;
          r = FuseStream(logs, setup, o);
        }
        const py::ssize_t n = static_cast<py::ssize_t>(r.size());
        std::vector<double> t, p, cov;
        std::vector<int> frame, dof;
        std::vector<Pose> T;
        py::list method, sensors, flagged, excluded, fault;
        for (const auto& s : r) {
          frame.push_back(s.frame);
          t.push_back(s.time_s);
          method.append(ToString(s.method));
          T.push_back(s.T_base_flange);
          Eigen::Matrix<double, 6, 6, Eigen::RowMajor> C = s.covariance;
          cov.insert(cov.end(), C.data(), C.data() + 36);
          sensors.append(py::cast(s.sensors));
          dof.push_back(s.dof);
          p.push_back(s.p_value);
          flagged.append(py::cast(s.flagged));
          excluded.append(py::cast(s.excluded));
          fault.append(s.fault);
        }
        py::dict d;
        d["frame"] = py::array(py::cast(frame));
        d["time_s"] = Array({n}, t.data());
        d["method"] = method;
        d["T_base_flange"] = PosesToArray(T);
        d["cov"] = Array({n, 6, 6}, cov.data());
        d["sensors"] = sensors;
        d["dof"] = py::array(py::cast(dof));
        d["p_value"] = Array({n}, p.data());
        d["flagged"] = flagged;
        d["excluded"] = excluded;
        d["fault"] = fault;
        return d;
      },
      py::arg("setup"), py::arg("tracker"), py::arg("robot") = py::none(), py::arg("inclinometer") = py::none(),
      py::arg("moifa") = true, py::arg("kalman") = true, py::arg("windows") = py::none(),
      "Fuses the tracker's poses with the robot's joints and/or the inclinometer (fusion/stream_fusion.h). "
      "Each stream is a file path (the CSVs of `mcms fuse`) or a dict of arrays: tracker {time_s, T_rig_target, "
      "cov[, frame]}, robot {time_s, q (rad/m)}, inclinometer {time_s, reading_rad}. windows: (K, 2) "
      "[start_s, end_s) standstill intervals, or None for one row per camera frame. Returns a dict of arrays "
      "(frame, time_s, method, T_base_flange (N, 4, 4), cov (N, 6, 6), p_value, ...), MOIFA before KF at equal times.");
}

}  // namespace

void BindRobot(py::module_& m) {
  BindRobotModel(m);
  BindRobotCalibration(m);
  BindFusion(m);
}

}  // namespace mcms::python
