// Python bindings: camera models and rigs, triangulation, the five-ball tracker, the
// camera audit and the field-of-view prediction.
// Long file: one translation unit on purpose (python/CMakeLists.txt: pybind11 is heavy to
// compile, and every binding here shares the argument converters above the bindings).
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>

#include "core/limits.h"
#include "audit/camera_audit.h"
#include "fusion/sensor_logs.h"
#include "jobs/fov_map.h"
#include "jobs/track_recording.h"
#include "python/py_common.h"
#include "tracking/fov_prediction.h"
#include "tracking/noise_estimate.h"
#include "tracking/sequence.h"
#include "tracking/target.h"
#include "tracking/tracker.h"
#include "vision/camera_model.h"
#include "vision/triangulation.h"

namespace mcms::python {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A frame number from Python: an int >= 0 (a negative one is named, not pybind's
// "incompatible function arguments").
size_t FrameIndex(long long frame) {
  if (frame < 0) Throw("argument 'frame': expected a frame number >= 0, got ", frame);
  return static_cast<size_t>(frame);
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool EndsWith(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// q, dq_dp, dq_dintrinsics for (3,) or (N, 3) points, as mrcal.project(get_gradients=True).
py::object Project(const CameraModel& cam, py::handle p_cam, bool get_gradients) {
  bool single = false;
  const std::vector<Vec3> p = GetPoints3(p_cam, "p_cam", &single);
  const py::ssize_t n = static_cast<py::ssize_t>(p.size()), ni = cam.NumIntrinsics();
  std::vector<double> q(2 * n), dq_dp(get_gradients ? 6 * n : 0), dq_di(get_gradients ? 2 * ni * n : 0);
  if (!get_gradients) {
    const std::vector<Vec2> r = cam.Project(p);
    for (py::ssize_t i = 0; i < n; ++i) q[2 * i] = r[i].x(), q[2 * i + 1] = r[i].y();
  } else {
    Eigen::Matrix<double, 2, 3> J;
    std::vector<double> Ji;
    for (py::ssize_t i = 0; i < n; ++i) {
      const Vec2 r = cam.Project(p[i], &J, &Ji);
      q[2 * i] = r.x(), q[2 * i + 1] = r.y();
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 3; ++b) dq_dp[6 * i + 3 * a + b] = J(a, b);
      std::copy(Ji.begin(), Ji.end(), dq_di.begin() + 2 * ni * i);
    }
  }
  auto shape = [&](std::vector<py::ssize_t> tail) {
    if (!single) tail.insert(tail.begin(), n);
    return tail;
  };
  py::array_t<double> q_out = Array(shape({2}), q.data());
  if (!get_gradients) return q_out;
  return py::make_tuple(q_out, Array(shape({2, 3}), dq_dp.data()), Array(shape({2, ni}), dq_di.data()));
}

// Unit rays; NaN rows where mrcal's unprojection does not converge. With gradients, the
// derivatives of the unit ray v: with J = dq/dv, the constraints project(v) = q and
// v.v = 1 give [J; v^T] dv = [dq; 0] and [J; v^T] dv = [-dq/dintrinsics dI; 0].
py::object Unproject(const CameraModel& cam, py::handle q_px, bool get_gradients) {
  bool single = false;
  const std::vector<Vec2> q = GetPoints2(q_px, "q", &single);
  const py::ssize_t n = static_cast<py::ssize_t>(q.size()), ni = cam.NumIntrinsics();
  const auto rays = cam.Unproject(q);
  std::vector<double> v(3 * n, kNaN), dv_dq(get_gradients ? 6 * n : 0, kNaN),
      dv_di(get_gradients ? 3 * ni * n : 0, kNaN);
  for (py::ssize_t i = 0; i < n; ++i) {
    if (!rays[i]) continue;
    const Vec3 r = rays[i]->normalized();
    std::copy(r.data(), r.data() + 3, v.begin() + 3 * i);
    if (!get_gradients) continue;
    Eigen::Matrix<double, 2, 3> J;
    std::vector<double> Ji;
    cam.Project(r, &J, &Ji);
    Mat3 M;
    M.topRows<2>() = J;
    M.row(2) = r.transpose();
    const Eigen::FullPivLU<Mat3> lu(M);
    if (!lu.isInvertible()) continue;
    const Mat3 Minv = lu.inverse();
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 2; ++b) dv_dq[6 * i + 2 * a + b] = Minv(a, b);
    Eigen::Map<const Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>> Jq(Ji.data(), 2, ni);
    Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor> Dv = -Minv.leftCols<2>() * Jq;
    std::copy(Dv.data(), Dv.data() + 3 * ni, dv_di.begin() + 3 * ni * i);
  }
  auto shape = [&](std::vector<py::ssize_t> tail) {
    if (!single) tail.insert(tail.begin(), n);
    return tail;
  };
  py::array_t<double> v_out = Array(shape({3}), v.data());
  if (!get_gradients) return v_out;
  return py::make_tuple(v_out, Array(shape({3, 2}), dv_dq.data()), Array(shape({3, ni}), dv_di.data()));
}

void WriteCamera(const CameraModel& cam, const std::string& path) {
  const std::string l = Lower(path);
  if (EndsWith(l, ".yaml") || EndsWith(l, ".yml"))
    cam.WriteOpenCvYaml(path);
  else
    cam.WriteCameramodel(path);
}

// Per camera: None (no image / no points) or an (N, 2) array of pixel centres, with
// optional (N, 2, 2) covariances (px^2), else sigma_px^2 I.
std::vector<std::optional<std::vector<ImagePoint>>> GetImagePoints(const CameraRig& rig, py::handle points,
                                                                   py::handle covariances, double sigma_px) {
  if (!(sigma_px > 0) || !std::isfinite(sigma_px))
    Throw("argument 'sigma_px': expected a positive number, got ", sigma_px);
  if (!py::isinstance<py::sequence>(points) || py::isinstance<py::str>(points))
    Throw("argument 'points': expected a list with one entry per camera (an (N, 2) array or None)");
  py::sequence seq = py::reinterpret_borrow<py::sequence>(points);
  if (seq.size() != rig.size())
    Throw("argument 'points': expected one entry per camera (", rig.size(), "), got ", seq.size());
  std::optional<py::sequence> covs;
  if (!covariances.is_none()) {
    if (!py::isinstance<py::sequence>(covariances))
      Throw("argument 'covariances': expected a list with one (N, 2, 2) array (or None) per camera");
    covs = py::reinterpret_borrow<py::sequence>(covariances);
    if (covs->size() != rig.size())
      Throw("argument 'covariances': expected one entry per camera (", rig.size(), "), got ", covs->size());
  }
  std::vector<std::optional<std::vector<ImagePoint>>> out(rig.size());
  for (size_t c = 0; c < rig.size(); ++c) {
    if (seq[c].is_none()) continue;
    const std::string name = "points[" + std::to_string(c) + "]";
    Numbers q = GetNumbers(seq[c], name, {{-1, 2}});
    std::vector<ImagePoint> v(static_cast<size_t>(q.dim(0)));
    for (size_t i = 0; i < v.size(); ++i) {
      v[i].q = Vec2(q.values[2 * i], q.values[2 * i + 1]);
      v[i].cov = Mat2::Identity() * sigma_px * sigma_px;
    }
    if (covs && !(*covs)[c].is_none()) {
      const std::string cname = "covariances[" + std::to_string(c) + "]";
      Numbers C = GetNumbers((*covs)[c], cname, {{static_cast<py::ssize_t>(v.size()), 2, 2}});
      for (size_t i = 0; i < v.size(); ++i) {
        Mat2 S = Eigen::Map<const Eigen::Matrix<double, 2, 2, Eigen::RowMajor>>(C.data() + 4 * i);
        if (std::abs(S(0, 1) - S(1, 0)) > 1e-12 * S.cwiseAbs().maxCoeff() || !(S(0, 0) > 0) || !(S.determinant() > 0))
          Throw("argument '", cname, "': covariance ", i, " is not symmetric positive definite");
        v[i].cov = S;
      }
    }
    out[c] = std::move(v);
  }
  return out;
}

py::dict PointDict(const TriangulatedPoint& p) {
  py::dict d;
  d["p_rig"] = Array({3}, p.p_rig.data());
  d["cov"] = Eigen::Matrix3d(p.cov);
  d["chi2"] = p.chi2;
  d["rms_px"] = p.rms_px;
  d["views"] = p.views();
  py::list obs;
  for (const auto& o : p.observations) obs.append(py::make_tuple(o.camera, o.index));
  d["observations"] = obs;
  return d;
}

py::object OptionalPose(const std::optional<Pose>& T) {
  if (!T) return py::none();
  return PoseToArray(*T);
}

// Tracker options from keyword arguments; unknown keys are errors naming the key.
TrackerOptions GetTrackerOptions(const py::kwargs& kw) {
  TrackerOptions o;
  for (auto item : kw) {
    const std::string key = py::str(item.first);
    auto num = [&]() {
      Numbers n = GetNumbers(item.second, key, {std::vector<py::ssize_t>{}});
      return n.values[0];
    };
    if (key == "polarity") {
      const std::string p = py::str(item.second);
      if (p == "bright")
        o.detector.polarity = Polarity::kBright;
      else if (p == "dark")
        o.detector.polarity = Polarity::kDark;
      else
        Throw("argument 'polarity': expected 'bright' or 'dark', got '", p, "'");
    } else if (key == "threshold_dn") {
      o.detector.threshold_dn = num();
    } else if (key == "read_noise_dn") {
      o.detector.read_noise_dn = num();
    } else if (key == "gain_e_per_dn") {
      o.detector.gain_e_per_dn = num();
    } else if (key == "camera_gain_e_per_dn") {
      Eigen::VectorXd g = GetVector(item.second, key);
      o.camera_gain_e_per_dn.assign(g.data(), g.data() + g.size());
    } else if (key == "min_margin") {
      o.min_margin = num();
    } else if (key == "max_fit_rms_m") {
      o.max_fit_rms_m = num();
    } else if (key == "association_gate_px") {
      o.association_gate_px = num();
    } else if (key == "max_chi2_per_dof") {
      o.max_chi2_per_dof = num();
    } else if (key == "max_prediction_age_s") {
      o.max_prediction_age_s = num();
    } else if (key == "gate_px") {
      o.matching.gate_px = num();
    } else if (key == "predicted_windows") {
      if (!py::isinstance<py::bool_>(item.second)) Throw("argument 'predicted_windows': expected True or False");
      o.predicted_windows = item.second.cast<bool>();
    } else if (key == "full_scan_every") {
      const double n = num();
      if (!(n >= 1 && n <= 1e9 && n == std::floor(n)))
        Throw("argument 'full_scan_every': expected a whole number of frames >= 1, got ", n);
      o.full_scan_every = static_cast<int>(n);
    } else {
      Throw("unknown tracker option '", key,
            "'; expected polarity, threshold_dn, read_noise_dn, gain_e_per_dn, camera_gain_e_per_dn, min_margin, "
            "max_fit_rms_m, association_gate_px, max_chi2_per_dof, max_prediction_age_s, gate_px, predicted_windows, "
            "full_scan_every");
    }
  }
  std::string why;
  if (!o.IsValid(&why)) Throw("tracker options: ", why);
  return o;
}

py::dict FovPointDict(const FovPointPrediction& p) {
  py::dict d;
  d["T_rig_target"] = PoseToArray(p.T_rig_target);
  d["trackable"] = p.trackable;
  d["cov"] = Mat6(p.cov);
  d["observations"] = p.observations;
  d["cameras_seeing"] = p.CamerasSeeing();
  d["balls_in_camera"] = p.balls_in_camera;
  d["mean_centre_sigma_px"] = p.mean_centre_sigma_px;
  d["mean_ball_px"] = p.mean_ball_px;
  d["min_border_px"] = p.min_border_px;
  std::vector<int> views;
  for (const auto& b : p.balls) views.push_back(b.views);
  d["ball_views"] = views;
  return d;
}

// The options shared by fov_map and predict_fov_points: the target's orientation in the rig
// (a rotation matrix, or None for the default) and the thread count.
FovMapOptions GetFovMapOptions(py::handle R_rig_target, int threads) {
  FovMapOptions o;
  if (!R_rig_target.is_none()) {
    Mat3 R = GetMatrix(R_rig_target, "R_rig_target", 3, 3);
    if ((R.transpose() * R - Mat3::Identity()).norm() > 1e-6 || R.determinant() < 0)
      Throw("argument 'R_rig_target': not a rotation matrix");
    o.R_rig_target = R;
  }
  CheckThreads(threads, "argument 'threads'", false);
  o.threads = threads;
  return o;
}

py::dict ErrorSummaryDict(const PoseErrorSummary& e, const std::string& truth_file) {
  py::dict d;
  d["frames"] = e.frames;
  d["ok"] = e.ok;
  d["degraded"] = e.degraded;
  d["lost"] = e.lost;
  d["evaluated"] = e.evaluated;
  d["position_rms_m"] = e.evaluated ? e.position_rms_m : kNaN;
  d["position_max_m"] = e.evaluated ? e.position_max_m : kNaN;
  d["rotation_rms_rad"] = e.evaluated ? e.rotation_rms_rad : kNaN;
  d["rotation_max_rad"] = e.evaluated ? e.rotation_max_rad : kNaN;
  d["predicted_position_rms_m"] = e.evaluated ? e.predicted_position_rms_m : kNaN;
  d["predicted_rotation_rms_rad"] = e.evaluated ? e.predicted_rotation_rms_rad : kNaN;
  d["mean_nees"] = e.evaluated ? e.mean_nees : kNaN;
  d["nees_band"] = py::make_tuple(e.evaluated ? e.nees_band_lo : kNaN, e.evaluated ? e.nees_band_hi : kNaN);
  d["nees_consistent"] = e.NeesInBand();
  d["description"] = DescribeTruthErrors(e, truth_file);
  return d;
}

std::optional<std::string> OptionalPath(py::handle h, const char* name) {
  if (h.is_none()) return std::nullopt;
  py::object fs = py::module_::import("os").attr("fspath");
  try {
    return py::str(fs(h)).cast<std::string>();
  } catch (py::error_already_set&) {
    Throw("argument '", name, "': expected a path (str or os.PathLike) or None, got a ",
          py::str(py::type::handle_of(h).attr("__name__")).cast<std::string>());
  }
}

}  // namespace

namespace {

void BindCameraModels(py::module_& m) {
  py::class_<CameraModel>(m, "CameraModel",
                          "A camera: mrcal lens model and intrinsics, image size, and its pose in the rig T_cam_rig.")
      .def(py::init(
               [](const std::string& lensmodel, py::handle intrinsics, int width, int height, py::handle T_cam_rig) {
                 Eigen::VectorXd in = GetVector(intrinsics, "intrinsics");
                 if (width <= 0 || height <= 0)
                   Throw("arguments 'width', 'height': expected a positive image size, got ", width, "x", height);
                 const Pose T = T_cam_rig.is_none() ? Pose::Identity() : GetPose(T_cam_rig, "T_cam_rig");
                 return CameraModel(lensmodel, std::vector<double>(in.data(), in.data() + in.size()), width, height, T);
               }),
           py::arg("lensmodel"), py::arg("intrinsics"), py::arg("width"), py::arg("height"),
           py::arg("T_cam_rig") = py::none())
      .def_static(
          "read", [](const std::string& path) { return CameraModel::Read(path); }, py::arg("path"),
          "Reads an mrcal .cameramodel or an OpenCV YAML file (by content).")
      .def("write", &WriteCamera, py::arg("path"),
           "Writes an mrcal .cameramodel, or OpenCV YAML when the name ends in .yaml/.yml.")
      .def_property_readonly("lensmodel", &CameraModel::LensModelName)
      .def_property(
          "intrinsics", [](const CameraModel& c) { return Array({c.NumIntrinsics()}, c.Intrinsics().data()); },
          [](CameraModel& c, py::handle v) {
            Eigen::VectorXd in = GetVector(v, "intrinsics", c.NumIntrinsics());
            c.MutableIntrinsics().assign(in.data(), in.data() + in.size());
          })
      .def_property_readonly("width", &CameraModel::Width)
      .def_property_readonly("height", &CameraModel::Height)
      .def_property_readonly("imagersize", [](const CameraModel& c) { return py::make_tuple(c.Width(), c.Height()); })
      .def_property(
          "T_cam_rig", [](const CameraModel& c) { return PoseToArray(c.T_cam_rig()); },
          [](CameraModel& c, py::handle T) { c.SetT_cam_rig(GetPose(T, "T_cam_rig")); })
      .def("project", &Project, py::arg("p_cam"), py::arg("get_gradients") = false,
           "Pixels of points in camera coordinates, (3,) or (N, 3). With get_gradients: (q, dq_dp, "
           "dq_dintrinsics) as mrcal.project.")
      .def("unproject", &Unproject, py::arg("q"), py::arg("get_gradients") = false,
           "Unit rays of pixels, (2,) or (N, 2); NaN where unprojection does not converge. With get_gradients: "
           "(v, dv_dq, dv_dintrinsics).")
      .def(
          "sees",
          [](const CameraModel& c, py::handle p, double margin) {
            std::vector<bool> r;
            for (const Vec3& x : GetPoints3(p, "p_cam")) r.push_back(c.Sees(x, margin));
            return r;
          },
          py::arg("p_cam"), py::arg("margin") = 0.0)
      .def(py::pickle(
          [](const CameraModel& c) {
            return py::make_tuple(c.LensModelName(), c.Intrinsics(), c.Width(), c.Height(), PoseToArray(c.T_cam_rig()));
          },
          [](py::tuple t) {
            if (t.size() != 5) throw std::runtime_error("mcms.CameraModel: bad pickle");
            Eigen::VectorXd in = GetVector(t[1], "intrinsics");
            return CameraModel(t[0].cast<std::string>(), std::vector<double>(in.data(), in.data() + in.size()),
                               t[2].cast<int>(), t[3].cast<int>(), GetPose(t[4], "T_cam_rig"));
          }))
      .def("__repr__", [](const CameraModel& c) {
        return "<mcms.CameraModel " + c.LensModelName() + " " + std::to_string(c.Width()) + "x" +
               std::to_string(c.Height()) + ">";
      });

  py::class_<CameraRig>(m, "CameraRig", "N cameras and their poses T_cam_rig in the common rig frame.")
      .def(py::init([](std::vector<CameraModel> cameras, std::optional<std::vector<std::string>> names) {
             CameraRig r;
             r.cameras = std::move(cameras);
             if (names) {
               if (names->size() != r.cameras.size())
                 Throw("argument 'names': expected one name per camera (", r.cameras.size(), "), got ", names->size());
               r.names = *names;
             } else {
               for (size_t i = 0; i < r.cameras.size(); ++i) r.names.push_back("cam" + std::to_string(i));
             }
             return r;
           }),
           py::arg("cameras"), py::arg("names") = py::none())
      .def_static(
          "read", [](const std::string& path) { return CameraRig::Read(path); }, py::arg("path"))
      .def(
          "write", [](const CameraRig& r, const std::string& path) { r.Write(path); }, py::arg("path"))
      .def_readonly("names", &CameraRig::names)
      .def_readonly("cameras", &CameraRig::cameras, "Copies of the cameras (as rig[i] and rig[name]).")
      .def(py::pickle([](const CameraRig& r) { return py::make_tuple(r.cameras, r.names); },
                      [](py::tuple t) {
                        if (t.size() != 2) throw std::runtime_error("mcms.CameraRig: bad pickle");
                        CameraRig r;
                        r.cameras = t[0].cast<std::vector<CameraModel>>();
                        r.names = t[1].cast<std::vector<std::string>>();
                        return r;
                      }))
      .def("__len__", &CameraRig::size)
      .def(
          "__getitem__",
          [](const CameraRig& r, py::object key) -> const CameraModel& {
            if (py::isinstance<py::str>(key)) {
              const std::string k = py::str(key);
              for (size_t i = 0; i < r.size(); ++i)
                if (r.names[i] == k) return r.cameras[i];
              throw py::key_error("no camera named '" + k + "' in the rig");
            }
            long i = key.cast<long>();
            if (i < 0) i += static_cast<long>(r.size());
            if (i < 0 || i >= static_cast<long>(r.size())) throw py::index_error("camera index out of range");
            return r.cameras[static_cast<size_t>(i)];
          },
          py::return_value_policy::copy)
      .def("__repr__", [](const CameraRig& r) { return "<mcms.CameraRig " + std::to_string(r.size()) + " cameras>"; });

  m.def(
      "triangulate",
      [](const CameraRig& rig, py::handle points, py::handle covariances, double sigma_px,
         double sphere_radius_m) -> py::object {
        // One 3-D point: per camera its pixel (2,) or None.
        if (!py::isinstance<py::sequence>(points))
          Throw("argument 'points': expected a list with one (2,) pixel (or None) per camera");
        py::sequence seq = py::reinterpret_borrow<py::sequence>(points);
        if (seq.size() != rig.size())
          Throw("argument 'points': expected one entry per camera (", rig.size(), "), got ", seq.size());
        py::list lists, covs;
        for (size_t c = 0; c < rig.size(); ++c) {
          if (seq[c].is_none()) {
            lists.append(py::none());
            covs.append(py::none());
            continue;
          }
          Numbers q = GetNumbers(seq[c], "points[" + std::to_string(c) + "]", {{2}});
          lists.append(Array({1, 2}, q.data()));
          if (covariances.is_none()) {
            covs.append(py::none());
          } else {
            if (!py::isinstance<py::sequence>(covariances))
              Throw("argument 'covariances': expected a list with one (2, 2) covariance (or None) per camera");
            py::sequence cs = py::reinterpret_borrow<py::sequence>(covariances);
            if (cs.size() != rig.size())
              Throw("argument 'covariances': expected one entry per camera (", rig.size(), "), got ", cs.size());
            if (cs[c].is_none()) {
              covs.append(py::none());
            } else {
              Numbers C = GetNumbers(cs[c], "covariances[" + std::to_string(c) + "]", {{2, 2}});
              covs.append(Array({1, 2, 2}, C.data()));
            }
          }
        }
        const auto pts = GetImagePoints(rig, lists, covs, sigma_px);
        std::vector<std::vector<ImagePoint>> per_cam(rig.size());
        std::vector<PointObservation> obs;
        for (size_t c = 0; c < rig.size(); ++c)
          if (pts[c]) {
            per_cam[c] = *pts[c];
            obs.push_back({static_cast<int>(c), 0});
          }
        TriangulationOptions o;
        o.sphere_radius_m = sphere_radius_m;
        std::string why;
        if (!o.IsValid(&why)) Throw("argument 'sphere_radius_m': ", why);
        const auto p = TriangulateNView(rig, per_cam, obs, o);
        if (!p) return py::none();
        return PointDict(*p);
      },
      py::arg("rig"), py::arg("points"), py::arg("covariances") = py::none(), py::arg("sigma_px") = 0.1,
      py::arg("sphere_radius_m") = 0.0,
      "N-view triangulation of one point seen at points[c] (pixel or None) in camera c. Returns a dict "
      "(p_rig, cov 3x3 m^2, chi2, rms_px, views, observations) or None (fewer than 2 views, parallel rays, "
      "behind a camera).");

  m.def(
      "match_and_triangulate",
      [](const CameraRig& rig, py::handle points, py::handle covariances, double sigma_px, double sphere_radius_m,
         double gate_px, int min_views) {
        const auto pts = GetImagePoints(rig, points, covariances, sigma_px);
        std::vector<std::vector<ImagePoint>> per_cam(rig.size());
        for (size_t c = 0; c < rig.size(); ++c)
          if (pts[c]) per_cam[c] = *pts[c];
        MatchingOptions o;
        o.gate_px = gate_px;
        o.min_views = min_views;
        o.triangulation.sphere_radius_m = sphere_radius_m;
        std::string why;
        if (!o.IsValid(&why)) Throw("matching options: ", why);
        py::list out;
        for (const auto& p : MatchAndTriangulate(rig, per_cam, o)) out.append(PointDict(p));
        return out;
      },
      py::arg("rig"), py::arg("points"), py::arg("covariances") = py::none(), py::arg("sigma_px") = 0.1,
      py::arg("sphere_radius_m") = 0.0, py::arg("gate_px") = 3.0, py::arg("min_views") = 2,
      "Matches unlabeled image points (per camera an (N, 2) array or None) across the rig and triangulates "
      "them. Returns a list of dicts as triangulate's; observations are (camera, index) pairs.");
}

void BindTracker(py::module_& m) {
  py::class_<Target>(m, "Target", "The five-ball target: ball centres (m, target frame) and radius.")
      .def(py::init([](py::handle balls, double ball_radius_m, const std::string& name) {
             Target t;
             t.name = name;
             t.balls_target = GetPoints3(balls, "balls");
             if (!(ball_radius_m > 0)) Throw("argument 'ball_radius_m': expected > 0, got ", ball_radius_m);
             t.ball_radius = ball_radius_m;
             t.MinDistanceGap();  // InputError when degenerate
             return t;
           }),
           py::arg("balls"), py::arg("ball_radius_m"), py::arg("name") = "five-ball")
      .def_static("default", &Target::Default)
      .def_static(
          "read", [](const std::string& path) { return Target::Read(path); }, py::arg("path"))
      .def(
          "write", [](const Target& t, const std::string& path) { t.Write(path); }, py::arg("path"))
      .def(py::pickle(
          [](const Target& t) { return py::make_tuple(Vec3sToArray(t.balls_target), t.ball_radius, t.name); },
          [](py::tuple p) {
            if (p.size() != 3) throw std::runtime_error("mcms.Target: bad pickle");
            Target t;
            t.balls_target = GetPoints3(p[0], "balls");
            t.ball_radius = p[1].cast<double>();
            t.name = p[2].cast<std::string>();
            return t;
          }))
      .def_readonly("name", &Target::name)
      .def_readonly("ball_radius_m", &Target::ball_radius)
      .def_property_readonly("balls", [](const Target& t) { return Vec3sToArray(t.balls_target); });

  py::class_<FrameResult>(m, "FrameResult", "The tracker's result for one frame.")
      .def_readonly("frame", &FrameResult::frame)
      .def_readonly("time_s", &FrameResult::time_s)
      .def_property_readonly("status", [](const FrameResult& r) { return std::string(ToString(r.status)); })
      .def_readonly("reason", &FrameResult::reason)
      .def_property_readonly("T_rig_target", [](const FrameResult& r) { return OptionalPose(r.T_rig_target); })
      .def_property_readonly(
          "cov", [](const FrameResult& r) { return Mat6(r.cov); },
          "6x6 covariance of T_rig_target, [dtheta; dp], rig frame, SI.")
      .def_readonly("points_triangulated", &FrameResult::points_triangulated)
      .def_readonly("balls_identified", &FrameResult::balls_identified)
      .def_readonly("cameras_used", &FrameResult::cameras_used)
      .def_readonly("observations", &FrameResult::observations)
      .def_readonly("identification_margin", &FrameResult::identification_margin)
      .def_readonly("rms_px", &FrameResult::rms_px)
      .def_readonly("chi2_per_dof", &FrameResult::chi2_per_dof)
      .def_readonly("point_of_ball", &FrameResult::point_of_ball)
      .def_property_readonly("points",
                             [](const FrameResult& r) {
                               std::vector<Vec3> p;
                               for (const auto& t : r.points) p.push_back(t.p_rig);
                               return Vec3sToArray(p);
                             })
      .def_property_readonly("image_points",
                             [](const FrameResult& r) {
                               py::list out;
                               for (const auto& cam : r.image_points) {
                                 std::vector<double> q;
                                 for (const auto& ip : cam) q.insert(q.end(), {ip.q.x(), ip.q.y()});
                                 out.append(Array({static_cast<py::ssize_t>(cam.size()), 2}, q.data()));
                               }
                               return out;
                             })
      .def("__repr__", [](const FrameResult& r) {
        return "<mcms.FrameResult frame " + std::to_string(r.frame) + " " + ToString(r.status) +
               (r.reason.empty() ? "" : " (" + r.reason + ")") + ">";
      });

  py::class_<Tracker>(
      m, "Tracker",
      "Sequence tracker of the five-ball target. Options as keywords: polarity, threshold_dn, "
      "read_noise_dn, gain_e_per_dn, camera_gain_e_per_dn, min_margin, max_fit_rms_m, "
      "association_gate_px, max_chi2_per_dof, max_prediction_age_s, gate_px, predicted_windows (detect in "
      "windows around the predicted ball images; see mcms track --predicted-windows), full_scan_every.")
      .def(py::init([](const CameraRig& rig, std::optional<Target> target, py::kwargs kw) {
             return Tracker(rig, target ? *target : Target::Default(), GetTrackerOptions(kw));
           }),
           py::arg("rig"), py::arg("target") = py::none())
      .def_property_readonly("window_detections", &Tracker::window_detections,
                             "camera images detected in predicted windows so far (predicted_windows=True)")
      .def_property_readonly("whole_image_detections", &Tracker::whole_image_detections,
                             "camera images detected whole so far with predicted_windows=True")
      .def(
          "process_frame",
          [](Tracker& t, py::handle images, long long frame_number, double time_s) {
            const size_t frame = FrameIndex(frame_number);
            const CameraRig& rig = t.rig();
            if (!py::isinstance<py::sequence>(images) || py::isinstance<py::str>(images))
              Throw("argument 'images': expected a list with one 2-D uint8/uint16 array (or None) per camera");
            py::sequence seq = py::reinterpret_borrow<py::sequence>(images);
            if (seq.size() != rig.size())
              Throw("argument 'images': expected one entry per camera (", rig.size(), "), got ", seq.size());
            std::vector<py::array> keep(rig.size());
            std::vector<cv::Mat> mats(rig.size());
            for (size_t c = 0; c < rig.size(); ++c) {
              if (seq[c].is_none()) continue;
              const std::string name = "images[" + std::to_string(c) + "]";
              py::array a = py::array::ensure(seq[c], py::array::c_style);
              if (!a) {
                PyErr_Clear();
                Throw("argument '", name, "': expected a 2-D uint8 or uint16 array");
              }
              const bool u8 = a.dtype().is(py::dtype::of<uint8_t>()), u16 = a.dtype().is(py::dtype::of<uint16_t>());
              if (!u8 && !u16)
                Throw("argument '", name, "': expected dtype uint8 or uint16, got ",
                      py::str(a.dtype()).cast<std::string>());
              const auto& cam = rig.cameras[c];
              if (a.ndim() != 2 || a.shape(0) != cam.Height() || a.shape(1) != cam.Width())
                Throw("argument '", name, "': expected a grey image of shape (", cam.Height(), ", ", cam.Width(),
                      ") for camera ", rig.names[c], ", got ndim ", a.ndim(),
                      a.ndim() >= 2
                          ? " shape (" + std::to_string(a.shape(0)) + ", " + std::to_string(a.shape(1)) + ", ...)"
                          : "");
              keep[c] = a;
              mats[c] = cv::Mat(static_cast<int>(a.shape(0)), static_cast<int>(a.shape(1)), u8 ? CV_8UC1 : CV_16UC1,
                                const_cast<void*>(a.data()));
            }
            // The GIL is kept: a Tracker carries state (its prediction) and must not run in two
            // Python threads at once. Use one Tracker per thread or process.
            return t.ProcessFrame(frame, time_s, mats);
          },
          py::arg("images"), py::arg("frame") = 0, py::arg("time_s") = 0.0,
          "Detects, matches, identifies and fits the target in one frame set: images[c] is camera c's grey "
          "image (uint8/uint16, shape (height, width)) or None. Frames in time order (the tracker predicts).")
      .def(
          "process_points",
          [](Tracker& t, py::handle points, long long frame_number, double time_s, py::handle covariances,
             double sigma_px) {
            const size_t frame = FrameIndex(frame_number);
            const auto pts = GetImagePoints(t.rig(), points, covariances, sigma_px);
            std::vector<std::string> problems(t.rig().size());
            for (size_t c = 0; c < pts.size(); ++c)
              if (!pts[c]) problems[c] = "no points given";
            return t.ProcessPoints(frame, time_s, pts, problems);
          },
          py::arg("points"), py::arg("frame") = 0, py::arg("time_s") = 0.0, py::arg("covariances") = py::none(),
          py::arg("sigma_px") = 0.1,
          "The same from blob centres: points[c] an (N, 2) array (or None) per camera, covariances (N, 2, 2) px^2 "
          "or sigma_px.")
      .def(
          "track_sequence",
          [](Tracker& t, const std::string& images_dir, std::optional<std::string> frames_csv, double frame_rate_hz,
             int threads) {
            if (!(frame_rate_hz > 0)) Throw("argument 'frame_rate_hz': expected > 0, got ", frame_rate_hz);
            CheckThreads(threads, "argument 'threads'", false);
            SequenceInput in;
            in.images_dir = images_dir;
            if (frames_csv) in.frames_csv = *frames_csv;
            in.frame_rate_hz = frame_rate_hz;
            const ImageSequence seq = ScanImageSequence(in, t.rig());
            return TrackImageSequence(seq, t, {}, threads);
          },
          py::arg("images_dir"), py::arg("frames_csv") = py::none(), py::arg("frame_rate_hz") = 10.0,
          py::arg("threads") = 1,
          "Tracks a recording on disk (images_dir/<camera name>/<frame>.png, optional frames.csv), as `mcms "
          "track`; returns the FrameResult of every frame.")
      .def_property_readonly("rig", &Tracker::rig)
      .def_property_readonly("target", &Tracker::target);
}

void BindTrackingResults(py::module_& m) {
  m.def(
      "estimate_sequence_noise",
      [](const CameraRig& rig, const std::string& images_dir, std::optional<std::string> frames_csv,
         double frame_rate_hz, int frames, const std::string& polarity, int threads) {
        if (!(frame_rate_hz > 0)) Throw("argument 'frame_rate_hz': expected > 0, got ", frame_rate_hz);
        if (frames < 1) Throw("argument 'frames': expected >= 1, got ", frames);
        CheckThreads(threads, "argument 'threads'", false);
        BlobDetectorOptions detector;
        if (polarity == "dark")
          detector.polarity = Polarity::kDark;
        else if (polarity != "bright")
          Throw("argument 'polarity': expected 'bright' or 'dark', got '", polarity, "'");
        SequenceInput in;
        in.images_dir = images_dir;
        if (frames_csv) in.frames_csv = *frames_csv;
        in.frame_rate_hz = frame_rate_hz;
        const ImageSequence seq = ScanImageSequence(in, rig);
        NoiseEstimateOptions o;
        o.frames = static_cast<size_t>(frames);
        SequenceNoiseModel n;
        {
          py::gil_scoped_release release;
          n = EstimateSequenceNoise(seq, rig, detector, o, threads);
        }
        py::dict d;
        d["cameras"] = n.cameras;
        d["gain_e_per_dn"] = n.gain_e_per_dn;
        d["cameras_differ"] = n.cameras_differ;
        d["homogeneity_chi2"] = n.homogeneity_chi2;
        d["homogeneity_dof"] = n.homogeneity_dof;
        d["frames_used"] = n.frames_used;
        d["description"] = n.Describe();
        return d;
      },
      py::arg("rig"), py::arg("images_dir"), py::arg("frames_csv") = py::none(), py::arg("frame_rate_hz") = 10.0,
      py::arg("frames") = 12, py::arg("polarity") = "bright", py::arg("threads") = 1,
      "The pixel-noise model of a recording from its own images, as `mcms track` measures it: per-camera "
      "gain_e_per_dn for Tracker(camera_gain_e_per_dn=...), and the description lines.");

  m.def(
      "results_to_arrays",
      [](const std::vector<FrameResult>& results) {
        const py::ssize_t n = static_cast<py::ssize_t>(results.size());
        std::vector<double> t, T, cov, rms;
        std::vector<long> frame;
        py::list status, reason;
        for (const auto& r : results) {
          frame.push_back(static_cast<long>(r.frame));
          t.push_back(r.time_s);
          status.append(ToString(r.status));
          reason.append(r.reason);
          Eigen::Matrix<double, 4, 4, Eigen::RowMajor> M = Eigen::Matrix<double, 4, 4, Eigen::RowMajor>::Constant(kNaN);
          Eigen::Matrix<double, 6, 6, Eigen::RowMajor> C = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>::Constant(kNaN);
          if (r.T_rig_target) {
            M.setIdentity();
            M.topLeftCorner<3, 3>() = r.T_rig_target->R;
            M.topRightCorner<3, 1>() = r.T_rig_target->t;
            C = r.cov;
          }
          T.insert(T.end(), M.data(), M.data() + 16);
          cov.insert(cov.end(), C.data(), C.data() + 36);
          rms.push_back(r.rms_px);
        }
        py::dict d;
        d["frame"] = py::array(py::cast(frame));
        d["time_s"] = Array({n}, t.data());
        d["status"] = status;
        d["reason"] = reason;
        d["T_rig_target"] = Array({n, 4, 4}, T.data());
        d["cov"] = Array({n, 6, 6}, cov.data());
        d["rms_px"] = Array({n}, rms.data());
        return d;
      },
      py::arg("results"),
      "The tracker's results as arrays: frame, time_s, status, reason, T_rig_target (N, 4, 4) and cov (N, 6, 6) "
      "(NaN where lost), rms_px.");

  m.def(
      "write_pose_csv",
      [](const std::string& path, const std::vector<FrameResult>& results) { WritePoseCsv(path, results); },
      py::arg("path"), py::arg("results"), "The pose CSV of `mcms track` (read by `mcms fuse` and mcms.fuse).");
}

void BindCameraAuditAndFieldOfView(py::module_& m) {
  m.def(
      "audit_cameras",
      [](const CameraRig& rig, const Target& target, const std::vector<FrameResult>& results, double false_alarm) {
        CameraAuditOptions o;
        o.false_alarm = false_alarm;
        std::string why;
        if (!o.IsValid(&why)) Throw("argument 'false_alarm': ", why);
        const CameraAuditResult a = AuditCameraModel(rig, target, results, o);
        py::dict d;
        d["report"] = a.report.Text();
        d["clean"] = a.report.clean;
        const auto Effect = [](const AuditEffect& e) {
          py::dict x;
          x["name"] = e.name;
          x["where"] = e.where;
          py::dict p, s;
          for (const auto& [k, v] : e.parameters) p[py::str(k)] = v;
          for (const auto& [k, v] : e.sigma) s[py::str(k)] = v;
          x["parameters"] = p;
          x["sigma"] = s;
          x["heldout_loglik_gain"] = e.heldout_loglik_gain;
          x["bic_gain"] = e.bic_gain;
          return x;
        };
        py::list effects, undecided;
        for (const auto& e : a.report.effects) effects.append(Effect(e));
        for (const auto& g : a.report.undecided) undecided.append(py::cast(g));
        d["effects"] = effects;
        d["undecided"] = undecided;
        d["noise_scale"] = py::cast(a.noise_scale);
        d["repaired_rig"] = a.ExtendedRig(rig);
        return d;
      },
      py::arg("rig"), py::arg("target"), py::arg("results"), py::arg("false_alarm") = 0.01,
      "The camera audit of tracked frames (audit/camera_audit.h, as `mcms audit cameras`): the catalog effects "
      "(camera_moved, focal_length, principal_point, radial_distortion, camera_time_offset, pixel_noise_scale, "
      "target_geometry) that earn their place, each with its size and sigma ('effects'), the undecided groups, the "
      "estimated noise scale per camera, the text report and the rig with the named effects applied "
      "('repaired_rig').");

  m.def(
      "predict_fov_point",
      [](const CameraRig& rig, const Target& target, py::handle T_rig_target, double centre_sigma_px) {
        if (!(centre_sigma_px > 0) || !std::isfinite(centre_sigma_px))
          Throw("argument 'centre_sigma_px': expected a positive number, got ", centre_sigma_px);
        const double v = centre_sigma_px * centre_sigma_px;
        return FovPointDict(PredictFovPoint(rig, target, GetPose(T_rig_target, "T_rig_target"),
                                            [v](const Ellipse&) { return Mat2(Mat2::Identity() * v); }));
      },
      py::arg("rig"), py::arg("target"), py::arg("T_rig_target"), py::arg("centre_sigma_px"),
      "Predicted (Cramer-Rao) precision of the tracker at one target pose, with an isotropic blob-centre noise.");

  m.def(
      "fov_map",
      [](const CameraRig& rig, const Target& target, const std::string& grid, py::handle R_rig_target, int threads,
         double threshold_mm, std::optional<std::string> output_dir) {
        FovMapOptions o = GetFovMapOptions(R_rig_target, threads);
        o.grid = FovGrid::Parse(grid, "argument 'grid'");
        o.threshold_mm = threshold_mm;
        std::string why;
        if (!o.IsValid(&why)) Throw("fov map options: ", why);
        FovMap map;
        {
          py::gil_scoped_release release;
          map = ComputeFovMap(rig, target, o);
          if (output_dir) WriteFovMap(map, *output_dir);
        }
        const py::ssize_t n = static_cast<py::ssize_t>(map.points.size());
        std::vector<Vec3> p;
        std::vector<double> sp, sr, sd, cov;
        std::vector<int> seeing;
        std::vector<bool> trackable;
        for (const auto& x : map.points) {
          p.push_back(x.p_rig);
          const Vec3 a = x.sigma_p(), b = x.sigma_r();
          sp.insert(sp.end(), a.data(), a.data() + 3);
          sr.insert(sr.end(), b.data(), b.data() + 3);
          sd.push_back(x.sigma_d());
          Eigen::Matrix<double, 6, 6, Eigen::RowMajor> C = x.prediction.cov;
          cov.insert(cov.end(), C.data(), C.data() + 36);
          seeing.push_back(x.prediction.CamerasSeeing());
          trackable.push_back(x.prediction.trackable);
        }
        py::dict d;
        d["shape"] = py::make_tuple(o.grid.n[2], o.grid.n[1], o.grid.n[0]);
        d["positions"] = Vec3sToArray(p);
        d["sigma_p"] = Array({n, 3}, sp.data());
        d["sigma_r"] = Array({n, 3}, sr.data());
        d["sigma_d"] = Array({n}, sd.data());
        d["cov"] = Array({n, 6, 6}, cov.data());
        d["cameras_seeing"] = py::array(py::cast(seeing));
        d["trackable"] = py::array(py::cast(trackable));
        d["summary"] = FovMapSummary(map);
        return d;
      },
      py::arg("rig"), py::arg("target"), py::arg("grid"), py::arg("R_rig_target") = py::none(), py::arg("threads") = 1,
      py::arg("threshold_mm") = 0.03, py::arg("output_dir") = py::none(),
      "The field-of-view map of `mcms fov-map` over grid 'x0:x1:nx,y0:y1:ny,z0:z1:nz' (m, rig frame; x fastest): "
      "arrays per grid point (reshape with 'shape' = (nz, ny, nx)), the summary text, and with output_dir the "
      "map.csv and figures of the CLI.");
}

void BindFieldOfViewGridAndJobs(py::module_& m) {
  m.def(
      "predict_fov_points",
      [](const CameraRig& rig, const Target& target, py::handle positions, py::handle R_rig_target, int threads) {
        const FovMapOptions o = GetFovMapOptions(R_rig_target, threads);
        const std::vector<Vec3> p = GetPoints3(positions, "positions");
        if (p.empty()) Throw("argument 'positions': expected at least one position");
        std::vector<FovMapPoint> r;
        {
          py::gil_scoped_release release;
          r = PredictFovPoints(rig, target, o, p);
        }
        const py::ssize_t n = static_cast<py::ssize_t>(r.size());
        std::vector<double> sp, sr, sd, mb, cov;
        std::vector<int> seeing;
        std::vector<bool> trackable;
        for (const auto& x : r) {
          const Vec3 a = x.sigma_p(), b = x.sigma_r();
          sp.insert(sp.end(), a.data(), a.data() + 3);
          sr.insert(sr.end(), b.data(), b.data() + 3);
          sd.push_back(x.sigma_d());
          mb.push_back(x.prediction.mean_ball_px);
          Eigen::Matrix<double, 6, 6, Eigen::RowMajor> C = x.prediction.cov;
          cov.insert(cov.end(), C.data(), C.data() + 36);
          seeing.push_back(x.prediction.CamerasSeeing());
          trackable.push_back(x.prediction.trackable);
        }
        py::dict d;
        d["positions"] = Vec3sToArray(p);
        d["sigma_p"] = Array({n, 3}, sp.data());
        d["sigma_r"] = Array({n, 3}, sr.data());
        d["sigma_d"] = Array({n}, sd.data());
        d["cov"] = Array({n, 6, 6}, cov.data());
        d["mean_ball_px"] = Array({n}, mb.data());
        d["cameras_seeing"] = py::array(py::cast(seeing));
        d["trackable"] = py::array(py::cast(trackable));
        return d;
      },
      py::arg("rig"), py::arg("target"), py::arg("positions"), py::arg("R_rig_target") = py::none(),
      py::arg("threads") = 1,
      "The field-of-view map's prediction at (N, 3) positions (rig frame, m): the detector's centre noise "
      "tabulated on rendered ball images, then sigma_p, sigma_r (N, 3; m, rad), sigma_d (N,), cov (N, 6, 6), "
      "NaN where not trackable.");

  m.def(
      "track_recording",
      [](py::handle dir, py::handle output, py::handle truth, py::handle images, py::handle rig, py::handle target,
         py::handle frames_csv, double frame_rate_hz, std::optional<double> gain_e_per_dn, double read_noise_dn,
         const std::string& polarity, double threshold_dn, int noise_frames, int threads) {
        TrackRecordingInput in;
        if (auto p = OptionalPath(dir, "dir")) in.dir = *p;
        if (auto p = OptionalPath(output, "output")) in.output = *p;
        if (auto p = OptionalPath(truth, "truth")) in.truth = *p;
        if (auto p = OptionalPath(images, "images")) in.images = *p;
        if (auto p = OptionalPath(rig, "rig")) in.rig = *p;
        if (auto p = OptionalPath(target, "target")) in.target = *p;
        if (auto p = OptionalPath(frames_csv, "frames_csv")) in.frames_csv = *p;
        in.rate_hz = frame_rate_hz;
        in.tracker.gain_e_per_dn = gain_e_per_dn;
        in.tracker.read_noise_dn = read_noise_dn;
        if (polarity == "dark")
          in.tracker.polarity = Polarity::kDark;
        else if (polarity != "bright")
          Throw("argument 'polarity': expected 'bright' or 'dark', got '", polarity, "'");
        in.tracker.threshold_dn = threshold_dn;
        if (noise_frames < 1) Throw("argument 'noise_frames': expected >= 1, got ", noise_frames);
        in.tracker.noise_frames = static_cast<size_t>(noise_frames);
        CheckThreads(threads, "argument 'threads'", false);
        in.tracker.threads = threads;
        TrackRecordingResult r;
        {
          // Minutes of work in C++: other Python threads (a dask worker's event loop) run meanwhile.
          py::gil_scoped_release release;
          r = TrackRecording(in);
        }
        py::dict d;
        d["output"] = r.output.string();
        d["images"] = r.images.string();
        d["truth"] = r.truth.empty() ? py::object(py::none()) : py::object(py::str(r.truth));
        d["frames"] = r.frames;
        d["ok"] = r.ok;
        d["degraded"] = r.degraded;
        d["lost"] = r.lost;
        d["residual_chi2_per_dof"] = r.residuals.dof > 0 ? r.residuals.Chi2PerDof() : kNaN;
        d["residuals_in_band"] = r.residuals.InBand();
        d["errors"] = r.errors ? py::object(ErrorSummaryDict(*r.errors, r.truth)) : py::object(py::none());
        d["notes"] = r.notes;
        d["seconds"] = r.seconds;
        return d;
      },
      py::arg("dir") = py::none(), py::kw_only(), py::arg("output") = py::none(), py::arg("truth") = py::none(),
      py::arg("images") = py::none(), py::arg("rig") = py::none(), py::arg("target") = py::none(),
      py::arg("frames_csv") = py::none(), py::arg("frame_rate_hz") = 0.0, py::arg("gain_e_per_dn") = py::none(),
      py::arg("read_noise_dn") = 0.0, py::arg("polarity") = "bright", py::arg("threshold_dn") = 0.0,
      py::arg("noise_frames") = 12, py::arg("threads") = 1,
      "Tracks one recording folder as `mcms track DIR` does (images/, rig.yaml, target.yaml, frames.csv; each can "
      "be given instead; frame_rate_hz 0 = not given: without a frames CSV frames are taken 10 Hz apart and the "
      "notes say so) and writes the pose CSV (default DIR/poses.csv). truth: a truth CSV of T_rig_target "
      "(what `mcms render` writes as truth/poses.csv), 'auto' (DIR/truth/poses.csv when it exists) or None. "
      "Returns a dict: output, images, truth, frames, ok, degraded, lost, residual_chi2_per_dof, residuals_in_band, "
      "errors (with a truth: as evaluate_poses returns, else None), notes (the CSV's '#' lines), seconds. Bad input "
      "raises mcms.InputError with the message of `mcms track`. The GIL is released while it runs.");

  m.def(
      "evaluate_poses",
      [](py::handle results, py::handle truth_csv) {
        const auto truth_path = OptionalPath(truth_csv, "truth_csv");
        if (!truth_path) Throw("argument 'truth_csv': expected the path of a truth CSV, got None");
        const std::string truth_file = *truth_path;
        const auto truth = ReadTruthPoses(truth_file);
        std::vector<FrameResult> frames;
        std::string source = "the results";
        if (py::isinstance<py::str>(results) || py::hasattr(results, "__fspath__")) {
          source = *OptionalPath(results, "results");
          const TrackerLog log = ReadTrackerLog(source);
          for (const TrackerSample& s : log.samples) {
            FrameResult r;
            r.frame = static_cast<size_t>(s.frame);
            r.time_s = s.time_s;
            r.status = FrameStatus::kOk;  // the CSV reader keeps tracked rows, not ok vs degraded
            r.T_rig_target = s.T_rig_target;
            r.cov = s.covariance;
            frames.push_back(std::move(r));
          }
          frames.resize(frames.size() + static_cast<size_t>(log.lost_rows));  // lost: no pose
        } else {
          try {
            frames = results.cast<std::vector<FrameResult>>();
          } catch (const py::cast_error&) {
            Throw("argument 'results': expected a list of mcms.FrameResult or the path of a pose CSV, got a ",
                  py::str(py::type::handle_of(results).attr("__name__")).cast<std::string>());
          }
        }
        return ErrorSummaryDict(EvaluateAgainstTruth(frames, truth, truth_file, source), truth_file);
      },
      py::arg("results"), py::arg("truth_csv"),
      "Errors of tracked poses against a truth CSV (frames matched by number, times must agree): results is a list "
      "of mcms.FrameResult or the path of a pose CSV (`mcms track` output; from a CSV, ok counts every tracked "
      "frame, ok or degraded). Returns a dict: frames, ok, degraded, lost, evaluated, position_rms_m, "
      "position_max_m, rotation_rms_rad, rotation_max_rad, predicted_position_rms_m, predicted_rotation_rms_rad, "
      "mean_nees, nees_band (95 %), nees_consistent, description (lines). NaN when no frame has a pose.");
}

}  // namespace

void BindVision(py::module_& m) {
  BindCameraModels(m);
  BindTracker(m);
  BindTrackingResults(m);
  BindCameraAuditAndFieldOfView(m);
  BindFieldOfViewGridAndJobs(m);
}

}  // namespace mcms::python
