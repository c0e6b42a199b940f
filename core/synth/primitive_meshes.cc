#include "core/synth/primitive_meshes.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace rpsr::core {
namespace {

constexpr float kTwoPi = 6.283185307179586f;

// Triangles of a grid of `rows` x `cols` vertices stored row-major from `first_vertex`; columns
// always wrap (the last column joins the first), rows wrap when `wrap_rows`. With rows running
// along the surface's "up" and columns counter-clockwise around it, the triangles face outward.
void AddGridTriangles(int first_vertex, int rows, int cols, bool wrap_rows, TriangleMesh& mesh) {
  const int row_steps = wrap_rows ? rows : rows - 1;
  for (int r = 0; r < row_steps; ++r) {
    const int r_next = (r + 1) % rows;
    for (int c = 0; c < cols; ++c) {
      const int c_next = (c + 1) % cols;
      const int a = first_vertex + r * cols + c;
      const int b = first_vertex + r * cols + c_next;
      const int d = first_vertex + r_next * cols + c_next;
      const int e = first_vertex + r_next * cols + c;
      mesh.triangles.emplace_back(a, b, d);
      mesh.triangles.emplace_back(a, d, e);
    }
  }
}

// Closes the ring of `cols` vertices starting at `ring_first` with a fan around a new vertex at
// `centre`. `faces_down` is true for the ring at the start of the row direction (its cap faces
// against the rows' direction).
void AddCapFan(const Eigen::Vector3f& centre, int ring_first, int cols, bool faces_down,
               TriangleMesh& mesh) {
  const int centre_index = static_cast<int>(mesh.vertices.size());
  mesh.vertices.push_back(centre);
  for (int c = 0; c < cols; ++c) {
    const int a = ring_first + c;
    const int b = ring_first + (c + 1) % cols;
    if (faces_down) {
      mesh.triangles.emplace_back(centre_index, b, a);
    } else {
      mesh.triangles.emplace_back(centre_index, a, b);
    }
  }
}

// sign(x) |x|^exponent: the superquadric's signed power.
float SignedPower(float x, float exponent) {
  const float magnitude = std::pow(std::abs(x), exponent);
  return x < 0.0f ? -magnitude : magnitude;
}

// Any unit vector perpendicular to unit `v`.
Eigen::Vector3f PerpendicularTo(const Eigen::Vector3f& v) {
  const Eigen::Vector3f helper =
      std::abs(v.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
  return v.cross(helper).normalized();
}

}  // namespace

TriangleMesh BoxMesh(const Eigen::Vector3f& half_extents) {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.emplace_back((i & 1) ? half_extents.x() : -half_extents.x(),
                               (i & 2) ? half_extents.y() : -half_extents.y(),
                               (i & 4) ? half_extents.z() : -half_extents.z());
  }
  // Each face as a counter-clockwise quad seen from outside.
  const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : faces) {
    mesh.triangles.emplace_back(f[0], f[1], f[2]);
    mesh.triangles.emplace_back(f[0], f[2], f[3]);
  }
  return mesh;
}

TriangleMesh FrustumMesh(float bottom_radius, float top_radius, float height, int segments) {
  return RevolutionMesh({{bottom_radius, -0.5f * height}, {top_radius, 0.5f * height}}, segments);
}

TriangleMesh CylinderBetween(const Eigen::Vector3f& from, const Eigen::Vector3f& to, float radius,
                             int segments) {
  const Eigen::Vector3f axis = to - from;
  const float length = axis.norm();
  const Eigen::Quaternionf rotation =
      Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitZ(), axis / length);
  Eigen::Affine3f pose = Eigen::Affine3f::Identity();
  pose.translate(0.5f * (from + to));
  pose.rotate(rotation);
  return TransformedMesh(FrustumMesh(radius, radius, length, segments), pose);
}

TriangleMesh SuperquadricMesh(const Eigen::Vector3f& half_axes, float epsilon1, float epsilon2,
                              int rings, int segments) {
  TriangleMesh mesh;
  const int rows = rings + 1;
  mesh.vertices.reserve(rows * segments);
  for (int r = 0; r < rows; ++r) {
    // Latitude from the south pole (-pi/2) to the north pole (+pi/2); pole rows collapse to a
    // point, which closes the surface.
    const float latitude = -0.5f * static_cast<float>(M_PI) + static_cast<float>(M_PI) * r / rings;
    const float cos_lat = (r == 0 || r == rings) ? 0.0f : std::cos(latitude);
    const float sin_lat = std::sin(latitude);
    for (int c = 0; c < segments; ++c) {
      const float longitude = kTwoPi * c / segments;
      const float ring = SignedPower(cos_lat, epsilon1);
      mesh.vertices.emplace_back(half_axes.x() * ring * SignedPower(std::cos(longitude), epsilon2),
                                 half_axes.y() * ring * SignedPower(std::sin(longitude), epsilon2),
                                 half_axes.z() * SignedPower(sin_lat, epsilon1));
    }
  }
  AddGridTriangles(0, rows, segments, /*wrap_rows=*/false, mesh);
  return mesh;
}

TriangleMesh EllipsoidMesh(const Eigen::Vector3f& half_axes, int rings, int segments) {
  return SuperquadricMesh(half_axes, 1.0f, 1.0f, rings, segments);
}

TriangleMesh TorusMesh(float major_radius, const std::vector<float>& tube_radii,
                       int minor_segments) {
  TriangleMesh mesh;
  const int major_segments = static_cast<int>(tube_radii.size());
  // Rows run around the tube (minor angle), columns around the z axis (major angle).
  for (int r = 0; r < minor_segments; ++r) {
    const float minor = kTwoPi * r / minor_segments;
    for (int c = 0; c < major_segments; ++c) {
      const float major = kTwoPi * c / major_segments;
      const float tube = tube_radii[c];
      const float distance = major_radius + tube * std::cos(minor);
      mesh.vertices.emplace_back(distance * std::cos(major), distance * std::sin(major),
                                 tube * std::sin(minor));
    }
  }
  AddGridTriangles(0, minor_segments, major_segments, /*wrap_rows=*/true, mesh);
  return mesh;
}

TriangleMesh RevolutionMesh(const std::vector<Eigen::Vector2f>& profile, int segments) {
  TriangleMesh mesh;
  const int rows = static_cast<int>(profile.size());
  for (const Eigen::Vector2f& radius_z : profile) {
    for (int c = 0; c < segments; ++c) {
      const float angle = kTwoPi * c / segments;
      mesh.vertices.emplace_back(radius_z.x() * std::cos(angle), radius_z.x() * std::sin(angle),
                                 radius_z.y());
    }
  }
  AddGridTriangles(0, rows, segments, /*wrap_rows=*/false, mesh);
  if (profile.front().x() > 0.0f) {
    AddCapFan({0.0f, 0.0f, profile.front().y()}, 0, segments, /*faces_down=*/true, mesh);
  }
  if (profile.back().x() > 0.0f) {
    AddCapFan({0.0f, 0.0f, profile.back().y()}, (rows - 1) * segments, segments,
              /*faces_down=*/false, mesh);
  }
  return mesh;
}

TriangleMesh LoftMesh(const std::vector<std::vector<Eigen::Vector2f>>& sections,
                      const std::vector<float>& heights) {
  TriangleMesh mesh;
  const int rows = static_cast<int>(sections.size());
  const int cols = static_cast<int>(sections.front().size());
  for (int r = 0; r < rows; ++r) {
    for (const Eigen::Vector2f& p : sections[r])
      mesh.vertices.emplace_back(p.x(), p.y(), heights[r]);
  }
  AddGridTriangles(0, rows, cols, /*wrap_rows=*/false, mesh);
  AddCapFan({0.0f, 0.0f, heights.front()}, 0, cols, /*faces_down=*/true, mesh);
  AddCapFan({0.0f, 0.0f, heights.back()}, (rows - 1) * cols, cols, /*faces_down=*/false, mesh);
  return mesh;
}

TriangleMesh TubeMesh(const std::vector<Eigen::Vector3f>& path, float radius, int sides) {
  TriangleMesh mesh;
  const int rows = static_cast<int>(path.size());
  Eigen::Vector3f previous_tangent = (path[1] - path[0]).normalized();
  Eigen::Vector3f normal = PerpendicularTo(previous_tangent);
  for (int r = 0; r < rows; ++r) {
    const Eigen::Vector3f& ahead = path[std::min(r + 1, rows - 1)];
    const Eigen::Vector3f& behind = path[std::max(r - 1, 0)];
    const Eigen::Vector3f tangent = (ahead - behind).normalized();
    // Parallel transport: turn the previous frame by the smallest rotation between tangents.
    normal = (Eigen::Quaternionf::FromTwoVectors(previous_tangent, tangent) * normal).normalized();
    normal = (normal - normal.dot(tangent) * tangent).normalized();
    const Eigen::Vector3f binormal = tangent.cross(normal);
    previous_tangent = tangent;
    for (int c = 0; c < sides; ++c) {
      const float angle = kTwoPi * c / sides;
      mesh.vertices.push_back(path[r] +
                              radius * (std::cos(angle) * normal + std::sin(angle) * binormal));
    }
  }
  AddGridTriangles(0, rows, sides, /*wrap_rows=*/false, mesh);
  AddCapFan(path.front(), 0, sides, /*faces_down=*/true, mesh);
  AddCapFan(path.back(), (rows - 1) * sides, sides, /*faces_down=*/false, mesh);
  return mesh;
}

TriangleMesh TransformedMesh(const TriangleMesh& mesh, const Eigen::Affine3f& pose) {
  TriangleMesh out;
  out.vertices.reserve(mesh.vertices.size());
  for (const Eigen::Vector3f& v : mesh.vertices) out.vertices.push_back(pose * v);
  out.triangles = mesh.triangles;
  if (pose.linear().determinant() < 0.0f) {
    for (Eigen::Vector3i& t : out.triangles) std::swap(t.y(), t.z());
  }
  return out;
}

void AppendMesh(const TriangleMesh& part, TriangleMesh& into) {
  const int offset = static_cast<int>(into.vertices.size());
  into.vertices.insert(into.vertices.end(), part.vertices.begin(), part.vertices.end());
  into.triangles.reserve(into.triangles.size() + part.triangles.size());
  for (const Eigen::Vector3i& t : part.triangles) {
    into.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
  }
}

double SurfaceArea(const TriangleMesh& mesh) {
  double area = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t.x()].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[t.y()].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[t.z()].cast<double>();
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

Eigen::Affine3f PlacedAt(const Eigen::Vector3f& translation, const Eigen::Vector3f& axis,
                         float angle_rad) {
  Eigen::Affine3f pose = Eigen::Affine3f::Identity();
  pose.translate(translation);
  pose.rotate(Eigen::AngleAxisf(angle_rad, axis.normalized()));
  return pose;
}

}  // namespace rpsr::core
