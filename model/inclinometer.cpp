#include "model/inclinometer.h"

#include <numbers>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"

namespace mcms {

bool Inclinometer::IsValid(std::string* why) const {
  std::ostringstream s;
  if (!R_flange_incl.allFinite() || (R_flange_incl.transpose() * R_flange_incl - Mat3::Identity()).norm() > 1e-9 ||
      R_flange_incl.determinant() < 0)
    s << "R_flange_incl must be a rotation matrix";
  else if (!bias.allFinite())
    s << "bias must be finite";
  else if (!(sigma > 0) || !std::isfinite(sigma))
    s << "sigma must be positive and finite, is " << sigma;
  else if (!(sigma <= 0.1))  // issue 53: 1e300 was taken; no tilt sensor is worse than 6 deg
    s << "sigma is " << sigma << " rad (" << sigma * 180 / std::numbers::pi
      << " deg); a tilt sensor's noise is at most 0.1 rad: is it in another unit?";
  else if (!(bias.cwiseAbs().maxCoeff() <= 0.1))
    s << "bias is (" << bias.x() << ", " << bias.y() << ") rad; a tilt sensor's zero is off by at most 0.1 rad";
  else if (!(period > 0) || !std::isfinite(period))
    s << "period must be positive and finite, is " << period;
  else if (!(range > 0) || !(range < 0.5 * std::numbers::pi))
    s << "range must be in (0, pi/2) rad, is " << range;
  if (s.tellp() == 0) return true;
  if (why) *why = "inclinometer: " + s.str();
  return false;
}

Vec2 Inclinometer::Tilt(const Mat3& R_base_flange, Eigen::Matrix<double, 2, 3>* d_tilt_d_dtheta) const {
  const Mat3 R_base_incl = R_base_flange * R_flange_incl;
  // Up (+z_base) in the sensor frame; its x and y components are the sines of the tilts.
  const Vec3 up_incl = R_base_incl.row(2).transpose();
  const double ux = std::clamp(up_incl.x(), -1.0, 1.0), uy = std::clamp(up_incl.y(), -1.0, 1.0);
  const Vec2 tilt(std::asin(ux), std::asin(uy));
  if (d_tilt_d_dtheta) {
    // R = Exp(dtheta) R_hat  =>  up_incl = R^T Exp(-dtheta) e_z ~ up_incl_hat + R_hat^T [e_z]x dtheta.
    const Mat3 d_up_d_dtheta = R_base_incl.transpose() * Skew(Vec3::UnitZ());
    d_tilt_d_dtheta->row(0) = d_up_d_dtheta.row(0) / std::sqrt(std::max(1.0 - ux * ux, 1e-300));
    d_tilt_d_dtheta->row(1) = d_up_d_dtheta.row(1) / std::sqrt(std::max(1.0 - uy * uy, 1e-300));
  }
  return tilt;
}

bool Inclinometer::InRange(const Mat3& R_base_flange) const {
  return Tilt(R_base_flange).cwiseAbs().maxCoeff() <= range;
}

std::optional<Vec2> Inclinometer::Simulate(const Mat3& R_base_flange, Rng& rng) const {
  if (!InRange(R_base_flange)) return std::nullopt;
  const Vec2 expected = Predict(R_base_flange);
  return Vec2(expected.x() + sigma * rng.Normal(), expected.y() + sigma * rng.Normal());
}

OrientationInformation Inclinometer::Constraint(const Vec2& reading, const Mat3& R_base_flange_lin) const {
  std::string why;
  if (!IsValid(&why)) Throw(why);
  if (!reading.allFinite()) Throw("inclinometer reading must be finite");
  Eigen::Matrix<double, 2, 3> H;
  const Vec2 tilt = Tilt(R_base_flange_lin, &H);
  if (tilt.cwiseAbs().maxCoeff() > range)
    Throw("inclinometer: linearization orientation tilts the sensor by ", tilt.cwiseAbs().maxCoeff() * 180.0 / std::numbers::pi,
          " deg, beyond its range ", range * 180.0 / std::numbers::pi, " deg");
  const double w = 1.0 / (sigma * sigma);
  OrientationInformation c;
  c.R_base_flange_lin = R_base_flange_lin;
  c.information = w * H.transpose() * H;
  c.information_vector = w * H.transpose() * (reading - tilt - bias);
  return c;
}

}  // namespace mcms
