// The Python module `mcms`: the module itself, its exceptions, the checked argument
// conversions of py_common.h and the pose helpers. The bindings proper are in
// py_vision.cpp (cameras, rigs, triangulation, tracker, audit, field-of-view map) and
// py_robot.cpp (robot models, IK, robot calibration, ISO 9283, fusion).
#include <cmath>
#include <sstream>

#include "core/output_folder.h"
#include "python/py_common.h"

namespace mcms::python {

namespace {

std::string ShapeText(const std::vector<py::ssize_t>& shape, bool pattern) {
  std::ostringstream s;
  s << "(";
  static const char* names[] = {"N", "M", "K", "L"};
  int unnamed = 0;
  for (size_t i = 0; i < shape.size(); ++i) {
    if (i) s << ", ";
    if (pattern && shape[i] < 0)
      s << names[std::min(unnamed++, 3)];
    else
      s << shape[i];
  }
  if (shape.size() == 1) s << ",";
  s << ")";
  return s.str();
}

bool Matches(const std::vector<py::ssize_t>& shape, const std::vector<py::ssize_t>& pattern) {
  if (shape.size() != pattern.size()) return false;
  for (size_t i = 0; i < shape.size(); ++i)
    if (pattern[i] >= 0 && shape[i] != pattern[i]) return false;
  return true;
}

}  // namespace

Numbers GetNumbers(py::handle h, const std::string& name, const std::vector<std::vector<py::ssize_t>>& shapes,
                   bool allow_nan) {
  std::string expected;
  for (size_t i = 0; i < shapes.size(); ++i) {
    if (i) expected += i + 1 == shapes.size() ? " or " : ", ";
    expected += ShapeText(shapes[i], true);
  }
  if (h.is_none()) Throw("argument '", name, "': expected an array of shape ", expected, ", got None");
  py::array a = py::array::ensure(h);
  if (!a) {
    PyErr_Clear();
    Throw("argument '", name, "': expected an array of shape ", expected, ", got a ",
          py::str(py::type::handle_of(h).attr("__name__")).cast<std::string>());
  }
  const char kind = a.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u')
    Throw("argument '", name, "': expected real numbers (float64), got dtype ",
          py::str(a.dtype()).cast<std::string>());
  Numbers n;
  n.shape.assign(a.shape(), a.shape() + a.ndim());
  bool ok = false;
  for (const auto& s : shapes) ok = ok || Matches(n.shape, s);
  if (!ok) Throw("argument '", name, "': expected shape ", expected, ", got ", ShapeText(n.shape, false));
  auto d = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  if (!d) throw py::error_already_set();
  n.values.assign(d.data(), d.data() + d.size());
  if (!allow_nan) {
    for (size_t i = 0; i < n.values.size(); ++i) {
      if (std::isfinite(n.values[i])) continue;
      // The element's index in the array's own shape.
      std::vector<py::ssize_t> index(n.shape.size());
      size_t rest = i;
      for (size_t k = n.shape.size(); k-- > 0;) {
        index[k] = static_cast<py::ssize_t>(rest % n.shape[k]);
        rest /= n.shape[k];
      }
      std::ostringstream at;
      for (size_t k = 0; k < index.size(); ++k) at << (k ? ", " : "") << index[k];
      Throw("argument '", name, "': element [", at.str(), "] is ", n.values[i], "; expected finite numbers");
    }
  }
  return n;
}

std::vector<Eigen::VectorXd> GetRows(py::handle h, const std::string& name, int k, bool* single) {
  Numbers n = GetNumbers(h, name, {{k}, {-1, k}});
  const bool one = n.shape.size() == 1;
  if (single) *single = one;
  const size_t rows = one ? 1 : static_cast<size_t>(n.dim(0));
  std::vector<Eigen::VectorXd> out(rows);
  for (size_t r = 0; r < rows; ++r) out[r] = Eigen::Map<const Eigen::VectorXd>(n.data() + r * k, k);
  return out;
}

std::vector<Vec3> GetPoints3(py::handle h, const std::string& name, bool* single) {
  std::vector<Vec3> out;
  for (const auto& r : GetRows(h, name, 3, single)) out.emplace_back(r);
  return out;
}

std::vector<Vec2> GetPoints2(py::handle h, const std::string& name, bool* single) {
  std::vector<Vec2> out;
  for (const auto& r : GetRows(h, name, 2, single)) out.emplace_back(r);
  return out;
}

Eigen::VectorXd GetVector(py::handle h, const std::string& name, int n) {
  Numbers v = GetNumbers(h, name, {{n}});
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.values.size()));
}

Eigen::MatrixXd GetMatrix(py::handle h, const std::string& name, int rows, int cols) {
  Numbers v = GetNumbers(h, name, {{rows, cols}});
  return Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      v.data(), v.dim(0), v.dim(1));
}

namespace {

Pose PoseFrom(const double* m, const std::string& name) {
  Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> T(m);
  if (std::abs(T(3, 0)) > 1e-12 || std::abs(T(3, 1)) > 1e-12 || std::abs(T(3, 2)) > 1e-12 ||
      std::abs(T(3, 3) - 1) > 1e-12)
    Throw(name, ": expected a rigid transform whose last row is [0, 0, 0, 1], got [", T(3, 0), ", ", T(3, 1),
          ", ", T(3, 2), ", ", T(3, 3), "]");
  Pose P;
  P.R = T.topLeftCorner<3, 3>();
  P.t = T.topRightCorner<3, 1>();
  const double err = (P.R.transpose() * P.R - Mat3::Identity()).norm();
  if (err > 1e-6 || P.R.determinant() < 0)
    Throw(name, ": the rotation part is not a rotation matrix (|R^T R - I| = ", err, ", det = ", P.R.determinant(),
          ")");
  // Re-orthonormalize the rounding of the caller's matrix away.
  P.R = Eigen::Quaterniond(P.R).normalized().toRotationMatrix();
  return P;
}

}  // namespace

Pose GetPose(py::handle h, const std::string& name) {
  Numbers n = GetNumbers(h, name, {{4, 4}});
  return PoseFrom(n.data(), "argument '" + name + "'");
}

std::vector<Pose> GetPoses(py::handle h, const std::string& name) {
  Numbers n = GetNumbers(h, name, {{-1, 4, 4}});
  std::vector<Pose> out;
  for (py::ssize_t i = 0; i < n.dim(0); ++i)
    out.push_back(PoseFrom(n.data() + 16 * i, "argument '" + name + "'[" + std::to_string(i) + "]"));
  return out;
}

Eigen::MatrixXd GetCovariance(py::handle h, const std::string& name, int n) {
  Eigen::MatrixXd C = GetMatrix(h, name, n, n);
  const double scale = C.cwiseAbs().maxCoeff();
  if ((C - C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * std::max(scale, 1e-300))
    Throw("argument '", name, "': expected a symmetric covariance matrix");
  Eigen::LLT<Eigen::MatrixXd> llt(C);
  if (llt.info() != Eigen::Success) Throw("argument '", name, "': expected a positive-definite covariance matrix");
  return C;
}

py::array_t<double> Array(const std::vector<py::ssize_t>& shape, const double* data) {
  py::array_t<double> a(shape);
  std::copy(data, data + a.size(), a.mutable_data());
  return a;
}

py::array_t<double> PoseToArray(const Pose& T) {
  Eigen::Matrix<double, 4, 4, Eigen::RowMajor> M = Eigen::Matrix<double, 4, 4, Eigen::RowMajor>::Identity();
  M.topLeftCorner<3, 3>() = T.R;
  M.topRightCorner<3, 1>() = T.t;
  return Array({4, 4}, M.data());
}

py::array_t<double> PosesToArray(const std::vector<Pose>& T) {
  py::array_t<double> a({static_cast<py::ssize_t>(T.size()), py::ssize_t{4}, py::ssize_t{4}});
  double* d = a.mutable_data();
  for (const Pose& P : T) {
    Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> M(d);
    M.setIdentity();
    M.topLeftCorner<3, 3>() = P.R;
    M.topRightCorner<3, 1>() = P.t;
    d += 16;
  }
  return a;
}

py::array_t<double> Vec3sToArray(const std::vector<Vec3>& v) {
  py::array_t<double> a({static_cast<py::ssize_t>(v.size()), py::ssize_t{3}});
  double* d = a.mutable_data();
  for (const Vec3& p : v) {
    std::copy(p.data(), p.data() + 3, d);
    d += 3;
  }
  return a;
}

}  // namespace mcms::python

PYBIND11_MODULE(mcms, m) {
  namespace py = pybind11;
  using namespace mcms;
  using namespace mcms::python;
  m.doc() =
      "mcms: multi-camera metrology (camera models and rigs, triangulation, the five-ball tracker, "
      "robot models and calibration, ISO 9283, sensor fusion, field-of-view maps).\n"
      "Poses are 4x4 numpy arrays T_a_b (p_a = T_a_b p_b), SI units (m, rad), pose covariances 6x6 "
      "in the [dtheta; dp] layout (rotation first). Bad input raises mcms.InputError (a ValueError) "
      "whose message names the argument or the file.";
  m.attr("__version__") = "0.1.0";
  py::register_exception<InputError>(m, "InputError", PyExc_ValueError);

  m.def(
      "require_outputs_spare_inputs",
      [](const std::vector<std::tuple<std::string, std::string, bool>>& outputs, const std::vector<std::string>& inputs) {
        std::vector<RunOutput> o;
        for (const auto& [path, what, folder] : outputs) o.push_back({path, what, folder});
        RequireOutputsSpareInputs(o, std::vector<std::filesystem::path>(inputs.begin(), inputs.end()));
      },
      py::arg("outputs"), py::arg("inputs"),
      "Never lose a user's data: raises mcms.InputError naming both when an output would overwrite or remove an "
      "input of the same run (the check of every mcms command). outputs: [(path, what, is_folder)] where what is "
      "how the user named it (e.g. 'batch -o'); inputs: [path]. The same file is found by device and inode, so "
      "symlinks and other spellings of a path are caught; inputs that do not exist are ignored.");

  m.def(
      "pose_from_rt",
      [](py::handle rt) {
        Eigen::VectorXd v = GetVector(rt, "rt", 6);
        return PoseToArray(Pose::FromRt(v.data()));
      },
      py::arg("rt"), "4x4 transform from mrcal's rt = [rotation vector (rad); translation (m)].");
  m.def(
      "rt_from_pose",
      [](py::handle T) {
        double rt[6];
        GetPose(T, "T").ToRt(rt);
        return Array({6}, rt);
      },
      py::arg("T"), "mrcal's rt = [rotation vector; translation] of a 4x4 transform.");
  m.def(
      "box_plus",
      [](py::handle T, py::handle delta) {
        Vec6 d = GetVector(delta, "delta", 6);
        return PoseToArray(BoxPlus(GetPose(T, "T"), d));
      },
      py::arg("T"), py::arg("delta"), "T perturbed by [dtheta; dp]: R = Exp(dtheta) R, p = p + dp.");
  m.def(
      "box_minus",
      [](py::handle T, py::handle T_hat) {
        Vec6 d = BoxMinus(GetPose(T, "T"), GetPose(T_hat, "T_hat"));
        return Array({6}, d.data());
      },
      py::arg("T"), py::arg("T_hat"), "[dtheta; dp] with T = box_plus(T_hat, result).");

  BindVision(m);
  BindRobot(m);
}
