// The image of a sphere. A camera sees a sphere of radius r centred at c as the cone
// of rays within asin(r/|c|) of the direction of c; through a pinhole that cone cuts
// the image plane in an ellipse whose centre is NOT the projection of c, and a lens
// bends it further. A blob detector measures the centroid of that outline, so the
// difference (the sphere-projection bias) must be removed before triangulating:
// it grows with the distance from the principal point and with r/|c|.
#pragma once

#include <vector>

#include "core/pose_math.h"
#include "vision/camera_model.h"

namespace mcms {

// Directions (unit vectors, camera frame) on the silhouette cone of a sphere.
std::vector<Vec3> SphereSilhouetteRays(const Vec3& centre_cam, double radius, int n);

// The sphere's outline in the image: the silhouette rays projected through the lens,
// as a closed polygon of n vertices. Empty when the sphere contains the camera centre.
std::vector<Vec2> SphereOutline(const CameraModel& cam, const Vec3& centre_cam, double radius, int n = 256);

// Area centroid of the sphere's image (what a centroiding detector measures on a
// uniformly bright disc), from the outline polygon by Green's theorem. Radius 0: a
// point, its projection (a board corner standing in for a ball; zero bias).
Vec2 SphereImageCentroid(const CameraModel& cam, const Vec3& centre_cam, double radius, int n = 256);

// Bias = SphereImageCentroid - Project(centre). Subtract it from a measured centroid
// to obtain the image of the sphere centre.
Vec2 SphereProjectionBias(const CameraModel& cam, const Vec3& centre_cam, double radius, int n = 256);

// An ellipse fitted to the outline (by its second area moments): centre, semi-axes
// (a >= b, pixels) and the angle of the major axis from +x (radians).
struct Ellipse {
  Vec2 centre;
  double a = 0, b = 0, angle = 0;
};
Ellipse EllipseFromOutline(const std::vector<Vec2>& outline);

}  // namespace mcms
