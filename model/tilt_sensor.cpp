#include "model/tilt_sensor.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "core/error.h"

namespace mcms {

void CheckAccelerometerReading(const Vec3& a, const std::string& where) {
  const double n = a.norm();
  if (std::isfinite(n) && std::abs(n / kStandardGravity - 1) <= 0.1) return;
  std::string unit;
  if (std::abs(n - 1) < 0.1) unit = " (in g?)";
  else if (std::abs(n / 1000 - 1) < 0.1) unit = " (in mg?)";
  Throw(where, ": an accelerometer reading (", a.x(), ", ", a.y(), ", ", a.z(), ") of norm ", n, unit,
        "; at rest it reads g, 9.81 m/s^2: expected m/s^2");
}

Mat3 TiltSince(const Vec3& a0, const Vec3& a) { return Eigen::Quaterniond::FromTwoVectors(a, a0).toRotationMatrix(); }

Pose TiltCorrection(const std::vector<Pose>& frames, std::vector<MeasuredTilt> tilts) {
  std::stable_sort(tilts.begin(), tilts.end(),
                   [](const MeasuredTilt& x, const MeasuredTilt& y) { return x.mount.frame < y.mount.frame; });
  std::vector<Mat3> A;
  for (const MeasuredTilt& t : tilts) {
    const Mat3 R = frames.at(t.mount.frame).R * t.mount.R_frame_link;
    A.push_back(R * t.D * R.transpose());
  }
  Pose C = Pose::Identity();
  for (size_t j = 0; j < tilts.size(); ++j) {
    const Vec3& o = frames[tilts[j].mount.frame].t;
    const Mat3 W = j == 0 ? A[0] : Mat3(A[j] * A[j - 1].transpose());
    C = C * Pose{W, o - W * o};
  }
  return C;
}

}  // namespace mcms
