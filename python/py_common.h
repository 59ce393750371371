// Shared by the translation units of the Python module: argument conversion with checks
// that name the argument (wrong dtype, wrong shape, NaN or Inf raise mcms.InputError, a
// ValueError), and numpy outputs. Poses cross the boundary as 4x4 homogeneous matrices
// T_a_b (docs/conventions.md), covariances in the [dtheta; dp] layout.
#pragma once

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "core/error.h"
#include "core/pose_math.h"

namespace mcms::python {

namespace py = pybind11;

// A checked argument: C-contiguous float64 values and the shape.
struct Numbers {
  std::vector<py::ssize_t> shape;
  std::vector<double> values;
  const double* data() const { return values.data(); }
  py::ssize_t dim(size_t i) const { return shape.at(i); }
};

// `h` converted to float64 (any real numeric dtype is accepted; bool, complex, strings and
// objects are not), its shape one of `shapes` (-1 = any size), every value finite unless
// `allow_nan`. InputError "argument 'NAME': ..." otherwise.
Numbers GetNumbers(py::handle h, const std::string& name, const std::vector<std::vector<py::ssize_t>>& shapes,
                   bool allow_nan = false);

// (k,) or (N, k): rows of k numbers; *single says which form it was.
std::vector<Eigen::VectorXd> GetRows(py::handle h, const std::string& name, int k, bool* single = nullptr);
std::vector<Vec3> GetPoints3(py::handle h, const std::string& name, bool* single = nullptr);
std::vector<Vec2> GetPoints2(py::handle h, const std::string& name, bool* single = nullptr);
// A vector of n numbers (n = -1: any length).
Eigen::VectorXd GetVector(py::handle h, const std::string& name, int n = -1);
// A rows x cols matrix (-1 = any).
Eigen::MatrixXd GetMatrix(py::handle h, const std::string& name, int rows, int cols);
// A 4x4 rigid transform: last row [0 0 0 1], rotation orthonormal with determinant +1.
Pose GetPose(py::handle h, const std::string& name);
// (N, 4, 4) rigid transforms.
std::vector<Pose> GetPoses(py::handle h, const std::string& name);
// A symmetric positive-definite n x n covariance.
Eigen::MatrixXd GetCovariance(py::handle h, const std::string& name, int n);

py::array_t<double> PoseToArray(const Pose& T);
py::array_t<double> PosesToArray(const std::vector<Pose>& T);
py::array_t<double> Array(const std::vector<py::ssize_t>& shape, const double* data);
py::array_t<double> Vec3sToArray(const std::vector<Vec3>& v);

// Registration of each part of the module (py_vision.cpp, py_robot.cpp).
void BindVision(py::module_& m);
void BindRobot(py::module_& m);

}  // namespace mcms::python
