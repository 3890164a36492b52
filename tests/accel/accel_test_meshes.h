// Generated meshes shared by the acceleration-structure tests (test_kdtree, test_bvh, test_grid):
// a triangle mesh with the view the structures take, and deterministic generators (UV sphere,
// cube, random soup, flat grid, degenerate triangles). Header-only; every random generator takes
// its own seed for a std::mt19937, so a test's meshes are the same on every run and platform.
#pragma once

#include "specula/accel/common/ray_query.h"
#include "specula/core/math.h"

#include <cmath>
#include <concepts>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace specula::accel::test {

/// Indexed triangles, with a name for failure messages.
struct Mesh {
  std::string name;
  std::vector<vec3> positions;
  std::vector<uvec3> triangles;

  [[nodiscard]] TriangleView view() const {
    return {positions.data(), triangles.data(), std::uint32_t(triangles.size())};
  }
  /// Appends a triangle with three vertices of its own.
  void add(const vec3& a, const vec3& b, const vec3& c) {
    const auto base = std::uint32_t(positions.size());
    positions.insert(positions.end(), {a, b, c});
    triangles.emplace_back(base, base + 1, base + 2);
  }
  /// The box of the finite vertices.
  [[nodiscard]] Aabb bounds() const {
    Aabb box;
    for (const vec3& p : positions)
      if (is_finite(p)) box.grow(p);
    return box;
  }
  void translate(const vec3& by) {
    for (vec3& p : positions) p += by;
  }
};

/// A UV sphere: rings + 1 rows of `segments` vertices from pole to pole (each pole row is one point
/// repeated). Each quad is split along its a-d diagonal. The pole rows' quads have one zero-area
/// triangle each, left out unless `pole_slivers` (then there are 2 · rings · segments triangles,
/// 2 · segments of them zero-area).
inline Mesh uv_sphere(int rings, int segments, float radius, const vec3& centre,
                      bool pole_slivers = false) {
  Mesh m{"sphere", {}, {}};
  constexpr float kPi = 3.14159265f;
  for (int i = 0; i <= rings; ++i) {
    const float theta = kPi * float(i) / float(rings);
    for (int j = 0; j < segments; ++j) {
      const float phi = 2.0f * kPi * float(j) / float(segments);
      m.positions.push_back(centre + radius * vec3(std::sin(theta) * std::cos(phi), std::cos(theta),
                                                   std::sin(theta) * std::sin(phi)));
    }
  }
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      const auto a = std::uint32_t(i * segments + j);
      const auto b = std::uint32_t(i * segments + (j + 1) % segments);
      const auto c = a + std::uint32_t(segments), d = b + std::uint32_t(segments);
      if (pole_slivers || i != 0) m.triangles.emplace_back(a, b, d);
      if (pole_slivers || i != rings - 1) m.triangles.emplace_back(a, d, c);
    }
  }
  return m;
}

/// The cube [-1, 1]^3: 8 shared vertices, 12 triangles.
inline Mesh cube() {
  Mesh m{"cube", {}, {}};
  for (int i = 0; i < 8; ++i)
    m.positions.emplace_back(float(i & 1) * 2.0f - 1.0f, float((i >> 1) & 1) * 2.0f - 1.0f,
                             float((i >> 2) & 1) * 2.0f - 1.0f);
  const std::uint32_t faces[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1},
                                     {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
  for (const auto& f : faces) {
    m.triangles.emplace_back(f[0], f[1], f[2]);
    m.triangles.emplace_back(f[0], f[2], f[3]);
  }
  return m;
}

/// `count` unconnected triangles with centres uniform in [-extent, extent]^3 and vertices at
/// centre + size(i) · (uniform in [-1, 1]^3); `size(i)` gives triangle i's size.
template <class SizeOf>
  requires std::invocable<SizeOf&, int>
inline Mesh random_soup(int count, std::uint32_t seed, float extent, SizeOf&& size_of) {
  Mesh m{"soup", {}, {}};
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  for (int i = 0; i < count; ++i) {
    const vec3 c(extent * unit(rng), extent * unit(rng), extent * unit(rng));
    const float size = float(size_of(i));
    m.add(c + size * vec3(unit(rng), unit(rng), unit(rng)),
          c + size * vec3(unit(rng), unit(rng), unit(rng)),
          c + size * vec3(unit(rng), unit(rng), unit(rng)));
  }
  return m;
}

/// The same with every triangle of about `size`.
inline Mesh random_soup(int count, std::uint32_t seed, float extent, float size) {
  return random_soup(count, seed, extent, [size](int) { return size; });
}

/// nx × ny quads (two triangles each, shared vertices) covering [lo, hi]^2 in the plane z = `z`.
/// Vertex x is lo + (hi - lo) · x / nx, so integer bounds with hi - lo = nx give exact integers.
inline Mesh flat_grid(int nx, int ny, float lo, float hi, float z = 0.0f) {
  Mesh m{"grid", {}, {}};
  for (int y = 0; y <= ny; ++y)
    for (int x = 0; x <= nx; ++x)
      m.positions.emplace_back(lo + (hi - lo) * float(x) / float(nx),
                               lo + (hi - lo) * float(y) / float(ny), z);
  for (int y = 0; y < ny; ++y)
    for (int x = 0; x < nx; ++x) {
      const auto a = std::uint32_t(y * (nx + 1) + x), b = a + 1, c = a + std::uint32_t(nx + 1),
                 d = c + 1;
      m.triangles.emplace_back(a, b, d);
      m.triangles.emplace_back(a, d, c);
    }
  return m;
}

/// Appends `count` degenerate or nearly degenerate triangles, each from a point a uniform in
/// [-extent, extent]^3 and a point b = a + span · (uniform in [-1, 1]^3), cycling through: a point (three equal vertices), a repeated vertex, a segment (a, b, a),
/// collinear vertices (midpoint and beyond the end), a needle (1e-6 wide), a sliver (1e-7 high),
/// a triangle flat in the plane z = extent, and — unless `finite_only` — one vertex NaN and one
/// vertex infinite (to be left out by the structures, never hit by brute force).
inline void add_degenerate_triangles(Mesh& m, int count, std::uint32_t seed, float extent,
                                     float span, bool finite_only = false) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  const int kinds = finite_only ? 8 : 10;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  for (int i = 0; i < count; ++i) {
    const vec3 a(extent * unit(rng), extent * unit(rng), extent * unit(rng));
    const vec3 b = a + span * vec3(unit(rng), unit(rng), unit(rng));
    switch (i % kinds) {
    case 0: m.add(a, a, a); break;                                     // a point
    case 1: m.add(a, a, b); break;                                     // a repeated vertex
    case 2: m.add(a, b, a); break;                                     // a segment
    case 3: m.add(a, 0.5f * (a + b), b); break;                        // collinear (midpoint)
    case 4: m.add(a, b, a + 2.0f * (b - a)); break;                    // collinear (beyond b)
    case 5: m.add(a, b, b + vec3(1e-6f, 0.0f, 0.0f)); break;           // a needle
    case 6: m.add(a, b, a + vec3(0.0f, 1e-7f, 1e-7f)); break;          // a sliver
    case 7:                                                            // flat in z = extent
      m.add(vec3(a.x, a.y, extent), vec3(b.x, b.y, extent), vec3(a.x, b.y, extent));
      break;
    case 8: m.add(a, b, vec3(kNaN, a.y, a.z)); break;                  // a NaN vertex
    default: m.add(a, vec3(kInf, b.y, b.z), b); break;                 // an infinite vertex
    }
  }
}

/// The brute-force property tests divide their ray counts by this in builds with assertions (the
/// asan preset, where the brute-force reference runs ~5x slower and memory errors show on fewer
/// rays as well); the optimised CI presets trace the full counts.
#ifdef NDEBUG
constexpr int kBruteForceDivisor = 1;
#else
constexpr int kBruteForceDivisor = 4;
#endif

} // namespace specula::accel::test
