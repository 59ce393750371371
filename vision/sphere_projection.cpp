#include "vision/sphere_projection.h"

#include <numbers>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <map>

namespace mcms {

namespace {
// (cos, sin) of 2 pi i / n for i = 0..n-1, computed once per n and thread: the outline of
// every sphere uses the same angles (the bias is evaluated ~100 times per frame set).
const std::vector<Vec2>& UnitCircle(int n) {
  thread_local std::map<int, std::vector<Vec2>> cache;
  std::vector<Vec2>& v = cache[n];
  if (v.empty()) {
    v.reserve(n);
    for (int i = 0; i < n; ++i) {
      const double phi = 2.0 * std::numbers::pi * i / n;
      v.emplace_back(std::cos(phi), std::sin(phi));
    }
  }
  return v;
}
}  // namespace

namespace {
// The silhouette rays into *rays (cleared first; empty when the sphere holds the centre).
void SilhouetteRaysInto(const Vec3& c, double r, int n, std::vector<Vec3>* out) {
  std::vector<Vec3>& rays = *out;
  rays.clear();
  const double d = c.norm();
  if (!(d > r) || n < 3) return;
  const Vec3 axis = c / d;
  // Any two unit vectors orthogonal to the axis.
  const Vec3 helper = std::abs(axis.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  const Vec3 e1 = axis.cross(helper).normalized();
  const Vec3 e2 = axis.cross(e1);
  const double sin_a = r / d, cos_a = std::sqrt(1.0 - sin_a * sin_a);
  rays.reserve(n);
  for (const Vec2& cs : UnitCircle(n)) rays.push_back(cos_a * axis + sin_a * (cs.x() * e1 + cs.y() * e2));
}
}  // namespace

std::vector<Vec3> SphereSilhouetteRays(const Vec3& c, double r, int n) {
  std::vector<Vec3> rays;
  SilhouetteRaysInto(c, r, n, &rays);
  return rays;
}

std::vector<Vec2> SphereOutline(const CameraModel& cam, const Vec3& c, double r, int n) {
  return cam.Project(SphereSilhouetteRays(c, r, n));
}

namespace {
// Signed area, centroid and (kSecond) the second central moments of a closed polygon
// (Green's theorem). The centroid alone, as the tracker's ~100 bias evaluations per frame
// set ask, skips the second moments' sums; the area and centroid are the same sums in the
// same order either way.
template <bool kSecond>
void PolygonMoments(const std::vector<Vec2>& p, double* area, Vec2* first, Mat2* second) {
  double A = 0, cx = 0, cy = 0, xx = 0, yy = 0, xy = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    const Vec2& a = p[i];
    const Vec2& b = p[i + 1 < p.size() ? i + 1 : 0];  // (an integer division per vertex cost more than the rest)
    const double cr = a.x() * b.y() - b.x() * a.y();
    A += cr;
    cx += (a.x() + b.x()) * cr;
    cy += (a.y() + b.y()) * cr;
    if constexpr (kSecond) {
      xx += (a.x() * a.x() + a.x() * b.x() + b.x() * b.x()) * cr;
      yy += (a.y() * a.y() + a.y() * b.y() + b.y() * b.y()) * cr;
      xy += (a.x() * b.y() + 2 * a.x() * a.y() + 2 * b.x() * b.y() + b.x() * a.y()) * cr;
    }
  }
  A *= 0.5;
  *area = A;
  *first = Vec2(cx, cy) / (6.0 * A);
  if constexpr (kSecond) {
    Mat2 M;
    M << xx / 12.0, xy / 24.0, xy / 24.0, yy / 12.0;
    M /= A;  // E[x x^T] over the area
    *second = M - (*first) * first->transpose();
  }
}
}  // namespace

Vec2 SphereImageCentroid(const CameraModel& cam, const Vec3& c, double r, int n) {
  // The tracker evaluates this ~100 times per frame set: the rays and the outline reuse
  // this thread's buffers instead of two allocations per call.
  if (r == 0) return cam.Project(c);  // a point (a board corner standing in for a ball)
  thread_local std::vector<Vec3> rays;
  thread_local std::vector<Vec2> outline;
  SilhouetteRaysInto(c, r, n, &rays);
  cam.Project(rays, &outline);
  if (outline.size() < 3) return cam.Project(c);
  double A;
  Vec2 m;
  PolygonMoments<false>(outline, &A, &m, nullptr);
  return m;
}

Vec2 SphereProjectionBias(const CameraModel& cam, const Vec3& c, double r, int n) {
  return SphereImageCentroid(cam, c, r, n) - cam.Project(c);
}

Ellipse EllipseFromOutline(const std::vector<Vec2>& outline) {
  Ellipse e;
  if (outline.size() < 3) return e;
  double A;
  Vec2 m;
  Mat2 S;
  PolygonMoments<true>(outline, &A, &m, &S);
  // A uniform ellipse with semi-axes a, b has second central moments a^2/4, b^2/4.
  Eigen::SelfAdjointEigenSolver<Mat2> es(S);
  e.centre = m;
  e.a = 2.0 * std::sqrt(std::max(es.eigenvalues()[1], 0.0));
  e.b = 2.0 * std::sqrt(std::max(es.eigenvalues()[0], 0.0));
  const Vec2 major = es.eigenvectors().col(1);
  e.angle = std::atan2(major.y(), major.x());
  return e;
}

}  // namespace mcms
