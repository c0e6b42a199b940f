// Closed triangle-mesh builders that the procedural shape families assemble objects from: boxes,
// frusta, superquadrics, tori, surfaces of revolution, lofted (extruded) star-shaped polygons and
// tubes swept along a path. Every builder returns a closed surface (pole and cap vertices close it)
// with counter-clockwise, outward-facing triangles, in a local frame documented per builder; parts
// are then placed with TransformedMesh and merged with AppendMesh. Assemblies of parts are unions
// of closed surfaces, not boolean-merged solids: good enough for surface sampling, which is all the
// benchmark needs.
#ifndef RPSR_CORE_SYNTH_PRIMITIVE_MESHES_H_
#define RPSR_CORE_SYNTH_PRIMITIVE_MESHES_H_

#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// Axis-aligned box centred at the origin with the given half extents (12 triangles).
TriangleMesh BoxMesh(const Eigen::Vector3f& half_extents);

// Capped frustum along +z from z = -height/2 (radius `bottom_radius`) to z = +height/2 (radius
// `top_radius`); a zero radius gives a cone. `segments` >= 3 around the axis.
TriangleMesh FrustumMesh(float bottom_radius, float top_radius, float height, int segments);

// Capped cylinder of `radius` whose axis runs from `from` to `to`.
TriangleMesh CylinderBetween(const Eigen::Vector3f& from, const Eigen::Vector3f& to, float radius,
                             int segments);

// Superquadric centred at the origin with half axes `half_axes`, north-south exponent `epsilon1`
// and east-west exponent `epsilon2` (1, 1 is an ellipsoid; small values are box-like, 2 is a
// diamond). `rings` latitude bands (>= 2), `segments` longitudes (>= 3).
TriangleMesh SuperquadricMesh(const Eigen::Vector3f& half_axes, float epsilon1, float epsilon2,
                              int rings, int segments);

// Ellipsoid centred at the origin: a superquadric with both exponents 1.
TriangleMesh EllipsoidMesh(const Eigen::Vector3f& half_axes, int rings, int segments);

// Torus around the z axis with `major_radius`; the tube's radius may vary around the ring: one
// radius per major segment (tube_radii.size() >= 3 segments), `minor_segments` around the tube.
TriangleMesh TorusMesh(float major_radius, const std::vector<float>& tube_radii,
                       int minor_segments);

// Surface of revolution about the z axis. `profile` lists (radius, z) from bottom to top (>= 2
// points, radii >= 0); ends with a positive radius are closed by a flat cap.
TriangleMesh RevolutionMesh(const std::vector<Eigen::Vector2f>& profile, int segments);

// Loft through polygon cross-sections in planes z = heights[k] (increasing). Every section lists
// the same number (>= 3) of vertices counter-clockwise and must be star-shaped about the origin
// (the end caps are fans from the origin). One polygon at two heights is a straight extrusion;
// rotating or scaling it from section to section twists or tapers the solid.
TriangleMesh LoftMesh(const std::vector<std::vector<Eigen::Vector2f>>& sections,
                      const std::vector<float>& heights);

// Tube of `radius` swept along the polyline `path` (>= 2 points, consecutive points distinct),
// with `sides` around it and flat caps at both ends. Cross-sections are carried along the path by
// parallel transport, so the tube does not twist.
TriangleMesh TubeMesh(const std::vector<Eigen::Vector3f>& path, float radius, int sides);

// `mesh` with every vertex mapped by `pose`. A pose with negative determinant flips the winding,
// so triangles are reversed to stay outward-facing.
TriangleMesh TransformedMesh(const TriangleMesh& mesh, const Eigen::Affine3f& pose);

// Appends `part`'s vertices and triangles (re-indexed) to `into`.
void AppendMesh(const TriangleMesh& part, TriangleMesh& into);

// Sum of triangle areas (double accumulation).
double SurfaceArea(const TriangleMesh& mesh);

// Rigid placement helper: rotation about `axis` (need not be unit) by `angle_rad`, then a
// translation.
Eigen::Affine3f PlacedAt(const Eigen::Vector3f& translation,
                         const Eigen::Vector3f& axis = Eigen::Vector3f::UnitZ(),
                         float angle_rad = 0.0f);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_PRIMITIVE_MESHES_H_
