#include "calib/registration.h"

#include <cmath>

#include <Eigen/Dense>

#include "core/error.h"

namespace mcms {

PlaneFit FitPlane(const std::vector<Vec3>& points) {
  if (points.size() < 3) Throw("plane fit: ", points.size(), " points; at least 3 are needed");
  PlaneFit f;
  for (const Vec3& p : points) f.centroid += p;
  f.centroid /= static_cast<double>(points.size());
  Mat3 C = Mat3::Zero();
  for (const Vec3& p : points) C += (p - f.centroid) * (p - f.centroid).transpose();
  const Eigen::SelfAdjointEigenSolver<Mat3> es(C);
  // Eigenvalues ascending: the normal is the direction of least spread.
  if (!(es.eigenvalues()[1] > 1e-12 * std::max(es.eigenvalues()[2], 1e-300)))
    Throw("plane fit: the points are collinear (or coincide); they define no plane");
  f.normal = es.eigenvectors().col(0);
  f.rms = std::sqrt(std::max(0.0, es.eigenvalues()[0]) / static_cast<double>(points.size()));
  return f;
}

CircleFit FitCircle3D(const std::vector<Vec3>& points) {
  const PlaneFit plane = FitPlane(points);
  // In-plane orthonormal axes.
  const Vec3 n = plane.normal;
  const Vec3 e1 = (std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
  const Vec3 e2 = n.cross(e1);
  const int m = static_cast<int>(points.size());
  std::vector<Vec2> uv(m);
  for (int i = 0; i < m; ++i) uv[i] = Vec2(e1.dot(points[i] - plane.centroid), e2.dot(points[i] - plane.centroid));
  // Kasa: u^2 + v^2 + D u + E v + F = 0, linear least squares.
  Eigen::MatrixXd A(m, 3);
  Eigen::VectorXd b(m);
  for (int i = 0; i < m; ++i) {
    A.row(i) << uv[i].x(), uv[i].y(), 1.0;
    b[i] = -uv[i].squaredNorm();
  }
  const Eigen::Vector3d s = A.colPivHouseholderQr().solve(b);
  Vec2 c(-s[0] / 2, -s[1] / 2);
  double r2 = c.squaredNorm() - s[2];
  if (!(r2 > 0) || !std::isfinite(r2)) Throw("circle fit: the points do not lie on a circular arc");
  double r = std::sqrt(r2);
  // Gauss-Newton on the geometric residuals |uv_i - c| - r (Kasa is biased for short arcs).
  for (int it = 0; it < 20; ++it) {
    Eigen::MatrixXd Jg(m, 3);
    Eigen::VectorXd res(m);
    for (int i = 0; i < m; ++i) {
      const Vec2 d = uv[i] - c;
      const double len = std::max(d.norm(), 1e-15);
      res[i] = len - r;
      Jg.row(i) << -d.x() / len, -d.y() / len, -1.0;
    }
    const Eigen::Vector3d step = Jg.colPivHouseholderQr().solve(-res);
    c += step.head<2>();
    r += step[2];
    if (step.norm() < 1e-14 * std::max(1.0, r)) break;
  }
  CircleFit f;
  f.centre = plane.centroid + c.x() * e1 + c.y() * e2;
  f.normal = n;
  f.radius = r;
  double ss = 0;
  for (const Vec2& p : uv) ss += std::pow((p - c).norm() - r, 2);
  f.rms = std::sqrt(ss / m);
  return f;
}

namespace {

// The measured axis direction, signed so that increasing the joint value turns the
// target counter-clockwise about it (right-hand rule), as the DH z axis does.
Vec3 SignedAxis(const CircleFit& c, const AxisSweep& s) {
  Vec3 acc = Vec3::Zero();
  for (size_t i = 1; i < s.p_meas.size(); ++i) {
    const double dq = s.q[i][s.axis] - s.q[i - 1][s.axis];
    const Vec3 turn = (s.p_meas[i - 1] - c.centre).cross(s.p_meas[i] - c.centre);
    acc += (dq >= 0 ? 1.0 : -1.0) * turn;
  }
  return acc.dot(c.normal) >= 0 ? c.normal : Vec3(-c.normal);
}

void CheckSweep(const RobotModel& robot, const AxisSweep& s, const char* which) {
  if (s.axis < 0 || s.axis >= robot.NumJoints())
    Throw("axis-circle registration: ", which, " turns joint ", s.axis + 1, " but robot '", robot.Name(), "' has ",
          robot.NumJoints(), " joints");
  if (robot.Joints()[s.axis].type != JointType::kRevolute)
    Throw("axis-circle registration: ", which, " turns joint ", s.axis + 1, ", which is prismatic; turn a revolute joint");
  if (s.q.size() != s.p_meas.size())
    Throw("axis-circle registration: ", which, " has ", s.q.size(), " joint vectors and ", s.p_meas.size(),
          " measured positions; give one position per joint vector");
  if (s.q.size() < 3)
    Throw("axis-circle registration: ", which, " has ", s.q.size(), " positions; at least 3 (better 8 or more over "
          "a wide arc) are needed for a circle fit");
  for (size_t i = 0; i < s.q.size(); ++i) {
    robot.CheckJoints(s.q[i]);
    for (int j = 0; j < robot.NumJoints(); ++j)
      if (j != s.axis && std::abs(s.q[i][j] - s.q[0][j]) > 1e-9)
        Throw("axis-circle registration: ", which, " position ", i + 1, " moves joint ", j + 1,
              " as well; only joint ", s.axis + 1, " may move in this sweep");
  }
}

}  // namespace

CircleRegistration RegisterByAxisCircles(const RobotModel& robot, const AxisSweep& sweep1, const AxisSweep& sweep2) {
  CheckSweep(robot, sweep1, "sweep 1");
  CheckSweep(robot, sweep2, "sweep 2");
  CircleRegistration out;
  out.circle1 = FitCircle3D(sweep1.p_meas);
  out.circle2 = FitCircle3D(sweep2.p_meas);
  out.axis1_meas = SignedAxis(out.circle1, sweep1);
  out.axis2_meas = SignedAxis(out.circle2, sweep2);

  // Nominal axis lines in the base frame at the sweeps' joint values.
  auto axis_line = [&](const AxisSweep& s, Vec3* dir, Vec3* point) {
    const JointAxis a = robot.AxisOf(robot.LinkFrames(s.q[0]), s.axis);
    *dir = a.w;
    *point = a.o;
  };
  Vec3 a1, o1, a2, o2;
  axis_line(sweep1, &a1, &o1);
  axis_line(sweep2, &a2, &o2);
  if (a1.cross(a2).norm() < 1e-3 || out.axis1_meas.cross(out.axis2_meas).norm() < 1e-3)
    Throw("axis-circle registration: the two swept axes are parallel; sweep two non-parallel axes (e.g. 1 and 2)");

  // Rotation from the two directions (TRIAD): frames u1 = axis 1, u2 = axis1 x axis2,
  // u3 = u1 x u2 built in both frames.
  auto triad = [](const Vec3& v1, const Vec3& v2) {
    Mat3 M;
    M.col(0) = v1.normalized();
    M.col(1) = v1.cross(v2).normalized();
    M.col(2) = M.col(0).cross(M.col(1));
    return M;
  };
  const Mat3 R = triad(out.axis1_meas, out.axis2_meas) * triad(a1, a2).transpose();

  // Translation: c1 = R (o1 + s a1) + t and c2 = R (o2 + u a2) + t, unknowns [t, s, u].
  Eigen::Matrix<double, 6, 5> A = Eigen::Matrix<double, 6, 5>::Zero();
  Eigen::Matrix<double, 6, 1> b;
  A.block<3, 3>(0, 0).setIdentity();
  A.block<3, 3>(3, 0).setIdentity();
  A.block<3, 1>(0, 3) = -(R * a1);
  A.block<3, 1>(3, 4) = -(R * a2);
  b.head<3>() = out.circle1.centre - R * o1;
  b.tail<3>() = out.circle2.centre - R * o2;
  const Eigen::Matrix<double, 5, 1> x = A.colPivHouseholderQr().solve(b);
  out.T_meas_base = Pose{R, x.head<3>()};
  return out;
}

RobotCalibrationResult RegisterLeastSquares(const RobotModel& robot, const std::vector<RobotMeasurement>& measurements,
                                            const RobotCalibrationOptions& options, const std::optional<Pose>& guess) {
  RobotCalibrationOptions o = options;
  o.estimate_dh = false;
  const Pose start = guess ? *guess : InitialBaseGuess(robot, measurements);
  return CalibrateRobot(robot, start, measurements, o);
}

}  // namespace mcms
