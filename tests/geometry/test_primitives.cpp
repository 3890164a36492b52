// Properties of the built-in primitives (engine/geometry/primitives.h): closed ones are
// watertight oriented 2-manifolds whose volume converges to the analytic one, faces point
// outward, normals are unit and agree with the winding, bounds match the parameters, and bad
// parameters throw specula::Error naming the problem.

#include "specula/core/error.h"
#include "specula/geometry/primitives.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

namespace {

using specula::Error;
using specula::make_primitive;
using specula::MeshSource;
using specula::TriangleMesh;
using specula::uvec3;
using specula::vec2;
using specula::vec3;

constexpr double kPi = std::numbers::pi;

MeshSource primitive(const std::string& name) {
  MeshSource s;
  s.kind = MeshSource::Kind::Primitive;
  s.primitive = name;
  return s;
}
MeshSource sphere(float radius, std::uint32_t segments, std::uint32_t rings) {
  MeshSource s = primitive("sphere");
  s.radius = radius;
  s.segments = segments;
  s.rings = rings;
  return s;
}
MeshSource box(vec3 size) {
  MeshSource s = primitive("box");
  s.size = size;
  return s;
}
MeshSource plane(float x, float z, std::uint32_t subdivisions) {
  MeshSource s = primitive("plane");
  s.size = vec3(x, 1.0f, z);
  s.rings = subdivisions;
  return s;
}
MeshSource round_solid(const std::string& name, float radius, float height, std::uint32_t segments,
                       float top_radius = 0.0f) {
  MeshSource s = primitive(name);
  s.top_radius = top_radius;
  s.radius = radius;
  s.height = height;
  s.segments = segments;
  return s;
}

/// A spread of closed primitives: coarsest allowed tessellations, odd counts, and finer ones.
std::vector<MeshSource> closed_primitives() {
  std::vector<MeshSource> out;
  for (const auto& [n, m] : {std::pair(3u, 2u), std::pair(4u, 3u), std::pair(7u, 5u), std::pair(32u, 16u)})
    out.push_back(sphere(1.5f, n, m));
  out.push_back(box(vec3(1.0f, 2.0f, 3.0f)));
  out.push_back(box(vec3(0.01f, 5.0f, 0.5f)));
  for (const std::uint32_t n : {3u, 5u, 16u, 64u}) {
    out.push_back(round_solid("cylinder", 0.75f, 2.0f, n));
    out.push_back(round_solid("cone", 0.75f, 2.0f, n));
    out.push_back(round_solid("cone", 0.75f, 2.0f, n, 0.25f)); // truncated
  }
  return out;
}

std::string describe(const MeshSource& s) {
  return s.primitive + " r=" + std::to_string(s.radius) + " h=" + std::to_string(s.height) +
         " segments=" + std::to_string(s.segments) + " rings=" + std::to_string(s.rings);
}

vec3 corner(const TriangleMesh& m, const uvec3& t, int k) { return m.positions[t[k]]; }
/// cross(p1 - p0, p2 - p0): the geometric normal of the winding, length twice the area.
vec3 face_normal(const TriangleMesh& m, const uvec3& t) {
  return glm::cross(corner(m, t, 1) - corner(m, t, 0), corner(m, t, 2) - corner(m, t, 0));
}
vec3 centroid(const TriangleMesh& m, const uvec3& t) {
  return (corner(m, t, 0) + corner(m, t, 1) + corner(m, t, 2)) / 3.0f;
}

/// Triangles re-indexed so that vertices at the same position share one index (seams, poles and
/// flat-shaded corners duplicate vertices for their normals and UVs).
struct Welded {
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::size_t vertex_count = 0;
};
Welded weld(const TriangleMesh& m) {
  std::map<std::array<float, 3>, std::uint32_t> ids;
  std::vector<std::uint32_t> remap(m.positions.size());
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const vec3& p = m.positions[i];
    remap[i] = ids.try_emplace({p.x, p.y, p.z}, std::uint32_t(ids.size())).first->second;
  }
  Welded w;
  w.vertex_count = ids.size();
  for (const uvec3& t : m.triangles) w.triangles.push_back({remap[t.x], remap[t.y], remap[t.z]});
  return w;
}

/// Signed volume by the divergence theorem: the sum over faces of det(p0, p1, p2) / 6.
double volume(const TriangleMesh& m) {
  double v = 0.0;
  for (const uvec3& t : m.triangles) {
    const glm::dvec3 a(corner(m, t, 0)), b(corner(m, t, 1)), c(corner(m, t, 2));
    v += glm::dot(a, glm::cross(b, c)) / 6.0;
  }
  return v;
}

double area(const TriangleMesh& m) {
  double total = 0.0;
  for (const uvec3& t : m.triangles) total += 0.5 * double(glm::length(face_normal(m, t)));
  return total;
}

// --- Topology -------------------------------------------------------------------------------

TEST(Primitives, ClosedPrimitivesAreWatertightOriented2Manifolds) {
  for (const MeshSource& source : closed_primitives()) {
    SCOPED_TRACE(describe(source));
    const TriangleMesh mesh = make_primitive(source, "test");
    const Welded w = weld(mesh);
    // Every directed edge once: with the manifold check below, each undirected edge is shared
    // by exactly two triangles that traverse it in opposite directions (consistent winding).
    std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
    for (const auto& t : w.triangles) {
      ASSERT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) << "degenerate after welding";
      for (int k = 0; k < 3; ++k) ++directed[{t[std::size_t(k)], t[std::size_t((k + 1) % 3)]}];
    }
    std::size_t undirected = 0;
    for (const auto& [edge, uses] : directed) {
      EXPECT_EQ(uses, 1) << "edge " << edge.first << "-" << edge.second << " repeated";
      const auto reverse = directed.find({edge.second, edge.first});
      EXPECT_TRUE(reverse != directed.end() && reverse->second == 1)
          << "edge " << edge.first << "-" << edge.second << " is on a boundary";
      undirected += edge.first < edge.second ? 1 : 0;
    }
    // Closed genus-0 surface: V - E + F = 2.
    EXPECT_EQ(std::int64_t(w.vertex_count) - std::int64_t(undirected) + std::int64_t(w.triangles.size()), 2);
    EXPECT_NO_THROW(mesh.validate("test"));
  }
}

TEST(Primitives, BoxHas24FlatShadedVerticesAnd12Triangles) {
  const TriangleMesh mesh = make_primitive(box(vec3(2.0f, 3.0f, 4.0f)), "test");
  EXPECT_EQ(mesh.vertex_count(), 24u);
  EXPECT_EQ(mesh.triangle_count(), 12u);
  EXPECT_EQ(weld(mesh).vertex_count, 8u) << "three copies of each corner, one per face";
  for (const uvec3& t : mesh.triangles) {
    const vec3 n = glm::normalize(face_normal(mesh, t));
    for (int k = 0; k < 3; ++k)
      EXPECT_LT(glm::length(mesh.normals[t[k]] - n), 1e-6f) << "flat faces carry the face normal";
  }
}

TEST(Primitives, PlaneIsASubdividedGridFacingUp) {
  for (const std::uint32_t n : {1u, 2u, 5u}) {
    SCOPED_TRACE(n);
    const TriangleMesh mesh = make_primitive(plane(3.0f, 2.0f, n), "test");
    EXPECT_EQ(mesh.triangle_count(), std::size_t(2) * n * n) << "n subdivisions per side";
    EXPECT_NEAR(area(mesh), 6.0, 1e-5);
    for (const uvec3& t : mesh.triangles) {
      const vec3 fn = face_normal(mesh, t);
      EXPECT_GT(fn.y, 0.0f) << "counter-clockwise seen from +Y";
      EXPECT_NEAR(0.5 * double(glm::length(fn)), 6.0 / (2.0 * n * n), 1e-5) << "uniform grid";
    }
    for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
      EXPECT_EQ(mesh.positions[i].y, 0.0f);
      EXPECT_EQ(mesh.normals[i], vec3(0, 1, 0));
    }
    // An open sheet: the boundary is the 4n rim edges, each used once.
    std::map<std::pair<std::uint32_t, std::uint32_t>, int> uses;
    for (const auto& t : weld(mesh).triangles)
      for (int k = 0; k < 3; ++k) {
        auto a = t[std::size_t(k)], b = t[std::size_t((k + 1) % 3)];
        ++uses[{std::min(a, b), std::max(a, b)}];
      }
    std::size_t boundary = 0;
    for (const auto& [edge, count] : uses) {
      EXPECT_LE(count, 2);
      boundary += count == 1 ? 1 : 0;
    }
    EXPECT_EQ(boundary, std::size_t(4) * n);
  }
}

// --- Volume ---------------------------------------------------------------------------------

/// Relative volume lost by inscribing with angular step x: 1 - sin(x)/x <= x^2 / 6.
double inscribed_loss(double step) { return step * step / 6.0; }

TEST(Primitives, VolumeConvergesToTheAnalyticVolume) {
  constexpr double kFloat = 1e-5; // float rounding of the vertex positions
  const float r = 1.25f, h = 3.0f;
  double previous_sphere = 1.0, previous_cylinder = 1.0, previous_cone = 1.0;
  for (const std::uint32_t n : {8u, 16u, 32u, 64u, 128u, 256u}) {
    SCOPED_TRACE(n);
    const double around = inscribed_loss(2.0 * kPi / n);

    // Prism and pyramid over an inscribed n-gon: only the polygon loses area.
    const double cylinder_exact = kPi * r * r * h;
    const double cylinder = volume(make_primitive(round_solid("cylinder", r, h, n), "test"));
    const double cylinder_error = (cylinder_exact - cylinder) / cylinder_exact;
    EXPECT_GE(cylinder_error, -kFloat) << "an inscribed solid cannot be larger";
    EXPECT_LE(cylinder_error, around + kFloat);

    const double cone_exact = kPi * r * r * h / 3.0;
    const double cone = volume(make_primitive(round_solid("cone", r, h, n), "test"));
    const double cone_error = (cone_exact - cone) / cone_exact;
    EXPECT_GE(cone_error, -kFloat);
    EXPECT_LE(cone_error, around + kFloat);

    // A frustum over inscribed n-gons: V = pi h (R^2 + R r + r^2) / 3, each area term scaled alike.
    const float top = 0.4f * r;
    const double frustum_exact = kPi * h * (r * r + r * top + top * top) / 3.0;
    const double frustum = volume(make_primitive(round_solid("cone", r, h, n, top), "test"));
    const double frustum_error = (frustum_exact - frustum) / frustum_exact;
    EXPECT_GE(frustum_error, -kFloat);
    EXPECT_LE(frustum_error, around + kFloat);

    // The sphere loses volume around the axis and along the pole-to-pole profile; the profile
    // term is weighted towards the equator, so it gets a factor 2 (its measured asymptote: 1.5).
    const std::uint32_t rings = n / 2;
    const double sphere_exact = 4.0 / 3.0 * kPi * r * r * r;
    const double sphere_volume = volume(make_primitive(sphere(r, n, rings), "test"));
    const double sphere_error = (sphere_exact - sphere_volume) / sphere_exact;
    EXPECT_GE(sphere_error, -kFloat);
    EXPECT_LE(sphere_error, around + 2.0 * inscribed_loss(kPi / rings) + kFloat);

    EXPECT_LT(cylinder_error, previous_cylinder) << "finer tessellation, smaller error";
    EXPECT_LT(cone_error, previous_cone);
    EXPECT_LT(sphere_error, previous_sphere);
    previous_cylinder = cylinder_error;
    previous_cone = cone_error;
    previous_sphere = sphere_error;
  }
  // Unequal tessellations: each direction's term bounds its own share.
  for (const auto& [n, m] : {std::pair(64u, 8u), std::pair(8u, 64u), std::pair(3u, 2u)}) {
    const double exact = 4.0 / 3.0 * kPi;
    const double error = (exact - volume(make_primitive(sphere(1.0f, n, m), "test"))) / exact;
    EXPECT_GE(error, -kFloat);
    EXPECT_LE(error, inscribed_loss(2.0 * kPi / n) + 2.0 * inscribed_loss(kPi / m) + kFloat)
        << n << " x " << m;
  }
}

TEST(Primitives, BoxVolumeIsTheProductOfItsEdges) {
  for (const vec3 size : {vec3(1.0f), vec3(2.0f, 3.0f, 4.0f), vec3(0.01f, 10.0f, 0.5f)}) {
    const double exact = double(size.x) * size.y * size.z;
    EXPECT_NEAR(volume(make_primitive(box(size), "test")), exact, 1e-6 * exact);
  }
}

// --- Orientation and normals ----------------------------------------------------------------

TEST(Primitives, FacesPointOutwardAndVertexNormalsAgree) {
  for (const MeshSource& source : closed_primitives()) {
    SCOPED_TRACE(describe(source));
    const TriangleMesh mesh = make_primitive(source, "test");
    ASSERT_EQ(mesh.normals.size(), mesh.vertex_count());
    for (std::size_t i = 0; i < mesh.triangle_count(); ++i) {
      const uvec3& t = mesh.triangles[i];
      const vec3 n = face_normal(mesh, t);
      ASSERT_GT(glm::length(n), 0.0f) << "degenerate triangle " << i;
      // Every primitive is convex around its centre (the origin), so outward means away from it.
      EXPECT_GT(glm::dot(n, centroid(mesh, t)), 0.0f) << "triangle " << i << " faces inward";
      for (int k = 0; k < 3; ++k)
        EXPECT_GT(glm::dot(n, mesh.normals[t[k]]), 0.0f)
            << "triangle " << i << ": vertex normal disagrees with the winding";
    }
  }
}

TEST(Primitives, VertexNormalsAreUnitAndUvsInRange) {
  std::vector<MeshSource> all = closed_primitives();
  all.push_back(plane(2.0f, 5.0f, 3));
  for (const MeshSource& source : all) {
    SCOPED_TRACE(describe(source));
    const TriangleMesh mesh = make_primitive(source, "test");
    ASSERT_EQ(mesh.uvs.size(), mesh.vertex_count());
    for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
      EXPECT_NEAR(glm::length(mesh.normals[i]), 1.0f, 1e-6f) << "vertex " << i;
      EXPECT_TRUE(mesh.uvs[i].x >= 0.0f && mesh.uvs[i].x <= 1.0f && mesh.uvs[i].y >= 0.0f &&
                  mesh.uvs[i].y <= 1.0f)
          << "vertex " << i;
    }
  }
}

TEST(Primitives, CurvedSurfacesHaveSmoothNormalsAndCapsFlatOnes) {
  const float r = 2.0f, h = 3.0f;
  const TriangleMesh ball = make_primitive(sphere(r, 24, 12), "test");
  for (std::size_t i = 0; i < ball.vertex_count(); ++i)
    EXPECT_LT(glm::length(ball.normals[i] - ball.positions[i] / r), 1e-5f) << "sphere normal = p / r";

  const TriangleMesh cylinder = make_primitive(round_solid("cylinder", r, h, 24), "test");
  const TriangleMesh cone = make_primitive(round_solid("cone", r, h, 24), "test");
  const float top = 0.5f;
  const TriangleMesh frustum = make_primitive(round_solid("cone", r, h, 24, top), "test");
  for (const TriangleMesh* mesh : {&cylinder, &cone, &frustum}) {
    for (const uvec3& t : mesh->triangles) {
      const vec3 n = glm::normalize(face_normal(*mesh, t));
      const bool cap = std::abs(n.y) > 1.0f - 1e-6f;
      for (int k = 0; k < 3; ++k) {
        const vec3 vn = mesh->normals[t[k]];
        if (cap) {
          EXPECT_EQ(vn, vec3(0.0f, n.y > 0 ? 1.0f : -1.0f, 0.0f)) << "caps are flat";
        } else {
          // Smooth side: the normal is the surface's, not the facet's, so it differs from the
          // facet normal, but it lies in the vertex's meridian plane.
          EXPECT_GT(glm::length(vn - n), 1e-4f) << "side normals are smooth, not per facet";
          const vec3 p = mesh->positions[t[k]];
          if (p.x != 0.0f || p.z != 0.0f) {
            EXPECT_NEAR(glm::dot(vn, glm::normalize(vec3(-p.z, 0.0f, p.x))), 0.0f, 1e-5f);
          }
        }
      }
    }
  }
  // Cylinder side normals are horizontal; cone side normals are orthogonal to the slant.
  for (std::size_t i = 0; i < cylinder.vertex_count(); ++i)
    if (cylinder.normals[i].y == 0.0f) {
      EXPECT_NEAR(glm::length(vec2(cylinder.positions[i].x, cylinder.positions[i].z)), r, 1e-5f);
    }
  for (const uvec3& t : cone.triangles)
    for (int k = 0; k < 3; ++k) {
      const vec3 p = cone.positions[t[k]];
      const vec3 n = cone.normals[t[k]];
      if (std::abs(n.y) == 1.0f || p.y > 0.0f) continue; // caps, and the apex (no radial direction)
      const vec3 slant = vec3(0.0f, 0.5f * h, 0.0f) - p;
      EXPECT_NEAR(glm::dot(n, glm::normalize(slant)), 0.0f, 1e-5f);
    }
  // The frustum's side normal is orthogonal to the slant line from its bottom rim to its top rim,
  // and points outwards and up; its top rim has the top radius.
  int top_rim = 0;
  for (std::size_t i = 0; i < frustum.vertex_count(); ++i) {
    const vec3 p = frustum.positions[i];
    const vec3 n = frustum.normals[i];
    if (std::abs(n.y) == 1.0f) continue;
    const vec2 out = glm::normalize(vec2(p.x, p.z));
    const vec3 slant = vec3(top * out.x, 0.5f * h, top * out.y) - vec3(r * out.x, -0.5f * h, r * out.y);
    EXPECT_NEAR(glm::dot(n, glm::normalize(slant)), 0.0f, 1e-5f);
    EXPECT_GT(glm::dot(vec2(n.x, n.z), out), 0.0f);
    EXPECT_GT(n.y, 0.0f);
    if (p.y > 0.0f) {
      ++top_rim;
      EXPECT_NEAR(glm::length(vec2(p.x, p.z)), top, 1e-5f);
    }
  }
  EXPECT_EQ(top_rim, 25);
}

TEST(Primitives, AConeTopRadiusOutsideZeroToRadiusIsAnError) {
  for (const float top : {-0.5f, 1.0f, 2.0f, std::numeric_limits<float>::quiet_NaN()}) {
    SCOPED_TRACE(top);
    EXPECT_THROW((void)make_primitive(round_solid("cone", 1.0f, 2.0f, 8, top), "test"), Error);
  }
}

// --- Bounds ---------------------------------------------------------------------------------

void expect_bounds(const TriangleMesh& mesh, vec3 lo, vec3 hi, float tolerance = 1e-6f) {
  const specula::Aabb b = mesh.bounds();
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(b.min[k], lo[k], tolerance) << "axis " << k;
    EXPECT_NEAR(b.max[k], hi[k], tolerance) << "axis " << k;
  }
}

TEST(Primitives, BoundsMatchTheParameters) {
  const float r = 1.5f, h = 4.0f;
  // Segment counts divisible by 4 put vertices on the +-X and +-Z axes, so the box is tight.
  expect_bounds(make_primitive(sphere(r, 32, 16), "test"), vec3(-r), vec3(r));
  expect_bounds(make_primitive(round_solid("cylinder", r, h, 16), "test"), vec3(-r, -h / 2, -r),
                vec3(r, h / 2, r));
  expect_bounds(make_primitive(round_solid("cone", r, h, 16), "test"), vec3(-r, -h / 2, -r),
                vec3(r, h / 2, r));
  expect_bounds(make_primitive(box(vec3(1.0f, 2.0f, 3.0f)), "test"), vec3(-0.5f, -1.0f, -1.5f),
                vec3(0.5f, 1.0f, 1.5f));
  expect_bounds(make_primitive(plane(4.0f, 6.0f, 3), "test"), vec3(-2.0f, 0.0f, -3.0f),
                vec3(2.0f, 0.0f, 3.0f));
  // Other counts stay inside the analytic bounds and reach them along Y.
  for (const std::uint32_t n : {3u, 5u, 7u}) {
    for (const MeshSource& s :
         {sphere(r, n, 3), round_solid("cylinder", r, h, n), round_solid("cone", r, h, n)}) {
      SCOPED_TRACE(describe(s));
      const specula::Aabb b = make_primitive(s, "test").bounds();
      const float half_y = s.primitive == "sphere" ? r : h / 2;
      EXPECT_EQ(b.min.y, -half_y);
      EXPECT_EQ(b.max.y, half_y);
      for (const int k : {0, 2}) {
        EXPECT_GE(b.min[k], -r);
        EXPECT_LE(b.max[k], r);
        EXPECT_GT(b.max[k] - b.min[k], r) << "spans more than a radius across";
      }
    }
  }
}

TEST(Primitives, AcceptsTheEndsOfTheDocumentedRanges) {
  EXPECT_NO_THROW(static_cast<void>(make_primitive(sphere(1.0f, 3, 2), "test")));
  EXPECT_NO_THROW(static_cast<void>(make_primitive(sphere(1.0f, 4096, 2), "test")));
  EXPECT_NO_THROW(static_cast<void>(make_primitive(sphere(1.0f, 3, 4096), "test")));
  EXPECT_NO_THROW(static_cast<void>(make_primitive(round_solid("cylinder", 1.0f, 1.0f, 3), "test")));
  EXPECT_NO_THROW(static_cast<void>(make_primitive(round_solid("cone", 1.0f, 1.0f, 4096), "test")));
  EXPECT_NO_THROW(static_cast<void>(make_primitive(plane(1.0f, 1.0f, 1), "test")));
  MeshSource flat = plane(1.0f, 1.0f, 4);
  flat.size.y = 0.0f; // a plane ignores size.y
  EXPECT_NO_THROW(static_cast<void>(make_primitive(flat, "test")));
}

TEST(Primitives, IsDeterministic) {
  for (const MeshSource& source : closed_primitives()) {
    const TriangleMesh a = make_primitive(source, "test");
    const TriangleMesh b = make_primitive(source, "test");
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.normals, b.normals);
    EXPECT_EQ(a.uvs, b.uvs);
    EXPECT_EQ(a.triangles, b.triangles);
  }
}

// --- Errors ---------------------------------------------------------------------------------

TEST(Primitives, BadParametersThrowErrorsNamingTheProblem) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  struct Case {
    MeshSource source;
    std::vector<std::string> mentions;
  };
  auto with = [](MeshSource s, auto change) {
    change(s);
    return s;
  };
  const std::vector<Case> cases = {
      {primitive("torus"), {"unknown primitive", "torus"}},
      {primitive(""), {"unknown primitive"}},
      {primitive("Sphere"), {"unknown primitive", "Sphere"}},
      {sphere(0.0f, 8, 4), {"sphere radius", "positive"}},
      {sphere(-1.0f, 8, 4), {"sphere radius", "-1"}},
      {sphere(nan, 8, 4), {"sphere radius", "finite"}},
      {sphere(inf, 8, 4), {"sphere radius", "finite"}},
      {sphere(1.0f, 2, 4), {"sphere segments", "[3, 4096]", "2"}},
      {sphere(1.0f, 4097, 4), {"sphere segments", "4097"}},
      {sphere(1.0f, 8, 1), {"sphere rings", "[2, 4096]"}},
      {sphere(1.0f, 8, 4097), {"sphere rings", "4097"}},
      {box(vec3(0.0f, 1.0f, 1.0f)), {"box size.x", "positive"}},
      {box(vec3(1.0f, -2.0f, 1.0f)), {"box size.y"}},
      {box(vec3(1.0f, 1.0f, nan)), {"box size.z", "finite"}},
      {box(vec3(inf, 1.0f, 1.0f)), {"box size.x", "finite"}},
      {plane(0.0f, 1.0f, 2), {"plane size.x"}},
      {plane(1.0f, -inf, 2), {"plane size.z"}},
      {plane(1.0f, 1.0f, 0), {"plane subdivisions", "[1, 4096]"}},
      {plane(1.0f, 1.0f, 4097), {"plane subdivisions"}},
      {round_solid("cylinder", 0.0f, 1.0f, 8), {"cylinder radius"}},
      {round_solid("cylinder", 1.0f, -1.0f, 8), {"cylinder height"}},
      {round_solid("cylinder", 1.0f, nan, 8), {"cylinder height", "finite"}},
      {round_solid("cylinder", 1.0f, 1.0f, 2), {"cylinder segments", "[3, 4096]"}},
      {round_solid("cone", inf, 1.0f, 8), {"cone radius", "finite"}},
      {round_solid("cone", 1.0f, 0.0f, 8), {"cone height"}},
      {round_solid("cone", 1.0f, 1.0f, 5000), {"cone segments", "5000"}},
      {with(sphere(1.0f, 8, 4), [](MeshSource& s) { s.radius = -0.0f; }), {"sphere radius"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(describe(c.source));
    try {
      static_cast<void>(make_primitive(c.source, "scene.json: meshes[3]"));
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.file(), "scene.json: meshes[3]") << "the context names where it came from";
      for (const std::string& word : c.mentions)
        EXPECT_NE(e.message().find(word), std::string::npos) << "'" << e.message() << "' lacks '" << word << "'";
    }
  }
}

} // namespace
