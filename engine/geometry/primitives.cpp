#include "specula/geometry/primitives.h"

#include "specula/core/error.h"

#include <cmath>
#include <cstdint>
#include <numbers>
#include <sstream>
#include <string>

namespace specula {
namespace {

constexpr std::uint32_t kMaxTessellation = 4096;

std::string format(float value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

/// Throws unless value is finite and > 0; `what` names the parameter ("sphere radius").
void require_positive(float value, const std::string& what, const std::string& context) {
  if (!std::isfinite(value) || !(value > 0.0f))
    throw Error(context, what + " must be finite and positive, got " + format(value));
}

/// Throws unless lo <= value <= hi; `what` names the parameter ("sphere segments").
void require_range(std::uint32_t value, std::uint32_t lo, std::uint32_t hi, const std::string& what,
                   const std::string& context) {
  if (value < lo || value > hi)
    throw Error(context, what + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                             "], got " + std::to_string(value));
}

/// Appends vertices and triangles to a mesh.
class Builder {
public:
  std::uint32_t vertex(const vec3& position, const vec3& normal, const vec2& uv) {
    mesh_.positions.push_back(position);
    mesh_.normals.push_back(normal);
    mesh_.uvs.push_back(uv);
    return static_cast<std::uint32_t>(mesh_.positions.size() - 1);
  }
  void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) { mesh_.triangles.emplace_back(a, b, c); }
  void reserve(std::size_t vertices, std::size_t triangles) {
    mesh_.positions.reserve(vertices);
    mesh_.normals.reserve(vertices);
    mesh_.uvs.reserve(vertices);
    mesh_.triangles.reserve(triangles);
  }
  [[nodiscard]] TriangleMesh take() { return std::move(mesh_); }

private:
  TriangleMesh mesh_;
};

/// (sin, cos) of the angle 2*pi*j/n, measured about +Y from +Z towards +X. Computed from j mod n,
/// so a seam column (j == n) repeats column 0 bit for bit and welds exactly with it.
vec2 around(std::uint32_t j, std::uint32_t n) {
  const double angle = 2.0 * std::numbers::pi * double(j % n) / double(n);
  return {float(std::sin(angle)), float(std::cos(angle))};
}

// All surfaces below follow one convention: a grid column index j grows with the angle about +Y
// (towards +X when seen from +Z) and a row index i grows downwards (or towards +Z on the plane).
// For the cell with corners a = (i, j), b = (i+1, j), c = (i+1, j+1), d = (i, j+1), the triangles
// (a, b, c) and (a, c, d) are counter-clockwise seen from outside: cross(b - a, c - a) points out.

TriangleMesh make_sphere(float radius, std::uint32_t segments, std::uint32_t rings) {
  Builder out;
  out.reserve(std::size_t(rings + 1) * (segments + 1), std::size_t(2) * segments * (rings - 1));
  for (std::uint32_t i = 0; i <= rings; ++i) {
    // The poles are set exactly: sin(pi) is not 0 in floating point.
    const double polar = std::numbers::pi * double(i) / double(rings);
    const float y = i == 0 ? 1.0f : i == rings ? -1.0f : float(std::cos(polar));
    const float ring_radius = i == 0 || i == rings ? 0.0f : float(std::sin(polar));
    for (std::uint32_t j = 0; j <= segments; ++j) {
      const vec2 sc = around(j, segments);
      const vec3 normal(ring_radius * sc.x, y, ring_radius * sc.y);
      out.vertex(radius * normal, glm::normalize(normal),
                 vec2(float(j) / float(segments), float(i) / float(rings)));
    }
  }
  const std::uint32_t row = segments + 1;
  for (std::uint32_t i = 0; i < rings; ++i)
    for (std::uint32_t j = 0; j < segments; ++j) {
      const std::uint32_t a = i * row + j, b = a + row, c = b + 1, d = a + 1;
      // At the poles one triangle of each cell collapses to a point pair; leave it out.
      if (i != rings - 1) out.triangle(a, b, c);
      if (i != 0) out.triangle(a, c, d);
    }
  return out.take();
}

TriangleMesh make_box(const vec3& size) {
  // Each face: outward normal n and in-face axes u, v with cross(u, v) == n, so the corners
  // -u-v, +u-v, +u+v, -u+v run counter-clockwise seen from outside.
  struct Face {
    vec3 n, u, v;
  };
  static const Face kFaces[] = {
      {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}, {{-1, 0, 0}, {0, 0, 1}, {0, 1, 0}},
      {{0, 1, 0}, {1, 0, 0}, {0, 0, -1}}, {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}},
      {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}},  {{0, 0, -1}, {-1, 0, 0}, {0, 1, 0}},
  };
  static constexpr float kCorners[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  const vec3 half = 0.5f * size;
  Builder out;
  out.reserve(24, 12);
  for (const Face& face : kFaces) {
    std::uint32_t first = 0;
    for (int k = 0; k < 4; ++k) {
      const float su = kCorners[k][0], sv = kCorners[k][1];
      // Components are exactly 0 or +-1, so corners shared by faces are bit-identical.
      const vec3 p = half * (face.n + su * face.u + sv * face.v);
      const std::uint32_t index = out.vertex(p, face.n, vec2(0.5f + 0.5f * su, 0.5f - 0.5f * sv));
      if (k == 0) first = index;
    }
    out.triangle(first, first + 1, first + 2);
    out.triangle(first, first + 2, first + 3);
  }
  return out.take();
}

TriangleMesh make_plane(float size_x, float size_z, std::uint32_t subdivisions) {
  const std::uint32_t n = subdivisions;
  Builder out;
  out.reserve(std::size_t(n + 1) * (n + 1), std::size_t(2) * n * n);
  for (std::uint32_t i = 0; i <= n; ++i) // rows along +Z
    for (std::uint32_t j = 0; j <= n; ++j) {
      const float s = float(j) / float(n), t = float(i) / float(n);
      out.vertex(vec3((s - 0.5f) * size_x, 0.0f, (t - 0.5f) * size_z), vec3(0, 1, 0), vec2(s, t));
    }
  for (std::uint32_t i = 0; i < n; ++i)
    for (std::uint32_t j = 0; j < n; ++j) {
      const std::uint32_t a = i * (n + 1) + j, b = a + n + 1, c = b + 1, d = a + 1;
      out.triangle(a, b, c);
      out.triangle(a, c, d);
    }
  return out.take();
}

/// A flat disc cap of `segments` rim vertices at height y, facing +Y (up) or -Y.
void add_cap(Builder& out, float radius, float y, std::uint32_t segments, bool up) {
  const vec3 normal(0.0f, up ? 1.0f : -1.0f, 0.0f);
  const std::uint32_t center = out.vertex(vec3(0.0f, y, 0.0f), normal, vec2(0.5f));
  for (std::uint32_t j = 0; j < segments; ++j) {
    const vec2 sc = around(j, segments);
    // Planar UVs, mirrored on the bottom so the texture reads the right way from outside.
    out.vertex(vec3(radius * sc.x, y, radius * sc.y), normal,
               vec2(0.5f + 0.5f * sc.x, up ? 0.5f - 0.5f * sc.y : 0.5f + 0.5f * sc.y));
  }
  for (std::uint32_t j = 0; j < segments; ++j) {
    const std::uint32_t rim = center + 1 + j, next = center + 1 + (j + 1) % segments;
    // Seen from +Y the angle grows counter-clockwise, so the top fan runs (center, j, j+1).
    if (up)
      out.triangle(center, rim, next);
    else
      out.triangle(center, next, rim);
  }
}

TriangleMesh make_cylinder(float radius, float height, std::uint32_t segments) {
  const float top = 0.5f * height, bottom = -0.5f * height;
  Builder out;
  out.reserve(std::size_t(2) * (segments + 1) + 2 * (segments + 1), std::size_t(4) * segments);
  for (std::uint32_t i = 0; i < 2; ++i)
    for (std::uint32_t j = 0; j <= segments; ++j) {
      const vec2 sc = around(j, segments);
      out.vertex(vec3(radius * sc.x, i == 0 ? top : bottom, radius * sc.y), vec3(sc.x, 0.0f, sc.y),
                 vec2(float(j) / float(segments), float(i)));
    }
  const std::uint32_t row = segments + 1;
  for (std::uint32_t j = 0; j < segments; ++j) {
    const std::uint32_t a = j, b = a + row, c = b + 1, d = a + 1;
    out.triangle(a, b, c);
    out.triangle(a, c, d);
  }
  add_cap(out, radius, top, segments, true);
  add_cap(out, radius, bottom, segments, false);
  return out.take();
}

TriangleMesh make_cone(float radius, float height, std::uint32_t segments) {
  const float apex_y = 0.5f * height, base_y = -0.5f * height;
  // The side's outward normal at angle a is (h sin a, r, h cos a) / sqrt(h^2 + r^2): orthogonal
  // to both the rim tangent and the slant line (-r sin a, h, -r cos a).
  const double slant = std::hypot(double(height), double(radius));
  const float radial = float(double(height) / slant), up = float(double(radius) / slant);
  Builder out;
  out.reserve(std::size_t(2) * segments + 1 + segments + 1, std::size_t(2) * segments);
  // The apex has no normal of its own: one apex vertex per segment, with the normal at the
  // segment's middle angle, keeps the shading smooth around the side.
  for (std::uint32_t j = 0; j < segments; ++j) {
    const double middle = 2.0 * std::numbers::pi * (double(j) + 0.5) / double(segments);
    const vec2 sc(float(std::sin(middle)), float(std::cos(middle)));
    out.vertex(vec3(0.0f, apex_y, 0.0f), vec3(radial * sc.x, up, radial * sc.y),
               vec2((float(j) + 0.5f) / float(segments), 0.0f));
  }
  const std::uint32_t rim = segments;
  for (std::uint32_t j = 0; j <= segments; ++j) {
    const vec2 sc = around(j, segments);
    out.vertex(vec3(radius * sc.x, base_y, radius * sc.y), vec3(radial * sc.x, up, radial * sc.y),
               vec2(float(j) / float(segments), 1.0f));
  }
  for (std::uint32_t j = 0; j < segments; ++j) out.triangle(j, rim + j, rim + j + 1);
  add_cap(out, radius, base_y, segments, false);
  return out.take();
}

/// A truncated cone: base `radius` at -height/2, `top_radius` (0 < top < radius) at +height/2,
/// both ends capped. The side normal is the cone's with r replaced by the radius difference.
TriangleMesh make_frustum(float radius, float top_radius, float height, std::uint32_t segments) {
  const float top = 0.5f * height, bottom = -0.5f * height;
  const double slant = std::hypot(double(height), double(radius) - double(top_radius));
  const float radial = float(double(height) / slant);
  const float up = float((double(radius) - double(top_radius)) / slant);
  Builder out;
  out.reserve(std::size_t(2) * (segments + 1) + 2 * (segments + 1), std::size_t(4) * segments);
  for (std::uint32_t i = 0; i < 2; ++i)
    for (std::uint32_t j = 0; j <= segments; ++j) {
      const vec2 sc = around(j, segments);
      const float r = i == 0 ? top_radius : radius;
      out.vertex(vec3(r * sc.x, i == 0 ? top : bottom, r * sc.y),
                 vec3(radial * sc.x, up, radial * sc.y), vec2(float(j) / float(segments), float(i)));
    }
  const std::uint32_t row = segments + 1;
  for (std::uint32_t j = 0; j < segments; ++j) {
    const std::uint32_t a = j, b = a + row, c = b + 1, d = a + 1;
    out.triangle(a, b, c);
    out.triangle(a, c, d);
  }
  add_cap(out, top_radius, top, segments, true);
  add_cap(out, radius, bottom, segments, false);
  return out.take();
}

} // namespace

TriangleMesh make_primitive(const MeshSource& source, const std::string& context) {
  const std::string& name = source.primitive;
  if (name == "sphere") {
    require_positive(source.radius, "sphere radius", context);
    require_range(source.segments, 3, kMaxTessellation, "sphere segments", context);
    require_range(source.rings, 2, kMaxTessellation, "sphere rings", context);
    return make_sphere(source.radius, source.segments, source.rings);
  }
  if (name == "box") {
    require_positive(source.size.x, "box size.x", context);
    require_positive(source.size.y, "box size.y", context);
    require_positive(source.size.z, "box size.z", context);
    return make_box(source.size);
  }
  if (name == "plane") {
    // size.y is ignored: a plane has no thickness.
    require_positive(source.size.x, "plane size.x", context);
    require_positive(source.size.z, "plane size.z", context);
    require_range(source.rings, 1, kMaxTessellation, "plane subdivisions (rings)", context);
    return make_plane(source.size.x, source.size.z, source.rings);
  }
  if (name == "cylinder" || name == "cone") {
    require_positive(source.radius, name + " radius", context);
    require_positive(source.height, name + " height", context);
    require_range(source.segments, 3, kMaxTessellation, name + " segments", context);
    if (name == "cylinder") return make_cylinder(source.radius, source.height, source.segments);
    if (source.top_radius == 0.0f) return make_cone(source.radius, source.height, source.segments);
    if (!(source.top_radius > 0.0f && source.top_radius < source.radius))
      throw Error(context, "cone top_radius must be in [0, radius), got " +
                               std::to_string(source.top_radius));
    return make_frustum(source.radius, source.top_radius, source.height, source.segments);
  }
  throw Error(context, "unknown primitive '" + name +
                           "' (expected sphere, box, plane, cylinder or cone)");
}

} // namespace specula
