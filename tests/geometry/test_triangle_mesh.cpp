// TriangleMesh (engine/geometry/triangle_mesh.h): validate() rejects each kind of bad mesh with
// an error naming it, compute_vertex_normals() gives unit area-weighted normals and copes with
// degenerate triangles, bounds() encloses exactly the positions.

#include "specula/core/error.h"
#include "specula/geometry/triangle_mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace {

using specula::Error;
using specula::TriangleMesh;
using specula::uvec3;
using specula::vec2;
using specula::vec3;

/// A tetrahedron with outward counter-clockwise faces, normals and UVs: valid as built.
TriangleMesh tetrahedron() {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  m.uvs = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
  m.compute_vertex_normals();
  return m;
}

/// A seeded random height field over an n x n grid: every triangle faces up (+Y).
TriangleMesh height_field(std::uint32_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> height(-0.3f, 0.3f);
  TriangleMesh m;
  for (std::uint32_t i = 0; i <= n; ++i)
    for (std::uint32_t j = 0; j <= n; ++j) m.positions.emplace_back(float(j), height(rng), float(i));
  for (std::uint32_t i = 0; i < n; ++i)
    for (std::uint32_t j = 0; j < n; ++j) {
      const std::uint32_t a = i * (n + 1) + j, b = a + n + 1;
      m.triangles.emplace_back(a, b, b + 1);
      m.triangles.emplace_back(a, b + 1, a + 1);
    }
  return m;
}

/// Expects validate() to throw an Error from `source` whose message contains every word.
void expect_invalid(const TriangleMesh& m, const std::vector<std::string>& words) {
  try {
    m.validate("mesh.obj");
    ADD_FAILURE() << "validate() accepted the mesh";
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), "mesh.obj") << "the error names the source";
    for (const std::string& w : words)
      EXPECT_NE(e.message().find(w), std::string::npos) << "'" << e.message() << "' lacks '" << w << "'";
  }
}

// --- validate -------------------------------------------------------------------------------

TEST(TriangleMeshValidate, AcceptsAWellFormedMesh) {
  EXPECT_NO_THROW(tetrahedron().validate("mesh.obj"));
  TriangleMesh bare = tetrahedron();
  bare.normals.clear(); // normals and UVs are optional
  bare.uvs.clear();
  EXPECT_NO_THROW(bare.validate("mesh.obj"));
}

TEST(TriangleMeshValidate, RejectsNonFiniteValues) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (const float bad : {nan, inf, -inf}) {
    SCOPED_TRACE(bad);
    for (int axis = 0; axis < 3; ++axis) {
      TriangleMesh m = tetrahedron();
      m.positions[2][axis] = bad;
      expect_invalid(m, {"vertex 2", "non-finite position"});
    }
    TriangleMesh n = tetrahedron();
    n.normals[1].y = bad;
    expect_invalid(n, {"vertex 1", "non-finite normal"});
    TriangleMesh t = tetrahedron();
    t.uvs[3].x = bad;
    expect_invalid(t, {"vertex 3", "non-finite texture coordinate"});
  }
}

TEST(TriangleMeshValidate, RejectsArraysOfTheWrongSize) {
  TriangleMesh fewer = tetrahedron();
  fewer.normals.pop_back();
  expect_invalid(fewer, {"3 normals", "4 vertices"});
  TriangleMesh more = tetrahedron();
  more.normals.push_back(vec3(0, 1, 0));
  expect_invalid(more, {"5 normals", "4 vertices"});
  TriangleMesh uvs = tetrahedron();
  uvs.uvs.push_back(vec2(0.5f));
  expect_invalid(uvs, {"5 texture coordinates", "4 vertices"});
}

TEST(TriangleMeshValidate, RejectsOutOfRangeIndices) {
  for (const std::uint32_t bad : {4u, 5u, 0xFFFFFFFFu}) {
    for (int corner = 0; corner < 3; ++corner) {
      TriangleMesh m = tetrahedron();
      m.triangles[3][corner] = bad;
      expect_invalid(m, {"triangle 3", std::to_string(bad), "4 vertices"});
    }
  }
}

TEST(TriangleMeshValidate, RejectsAMeshWithoutTriangles) {
  TriangleMesh m = tetrahedron();
  m.triangles.clear();
  expect_invalid(m, {"no triangles"});
  expect_invalid(TriangleMesh{}, {"no triangles"});
}

// --- compute_vertex_normals -----------------------------------------------------------------

TEST(TriangleMeshNormals, AreUnitAndFaceTheWindingSide) {
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    TriangleMesh m = height_field(12, seed);
    m.normals.assign(3, vec3(7.0f)); // stale normals are replaced, whatever their count
    m.compute_vertex_normals();
    ASSERT_EQ(m.normals.size(), m.positions.size());
    for (const vec3& n : m.normals) {
      EXPECT_NEAR(glm::length(n), 1.0f, 1e-6f);
      EXPECT_GT(n.y, 0.0f) << "every triangle of a height field faces +Y";
    }
    EXPECT_NO_THROW(m.validate("field"));
  }
  // A closed convex solid: every normal points away from the interior.
  const TriangleMesh t = tetrahedron();
  const vec3 inside(0.25f);
  for (std::size_t i = 0; i < t.positions.size(); ++i)
    EXPECT_GT(glm::dot(t.normals[i], t.positions[i] - inside), 0.0f) << "vertex " << i;
}

TEST(TriangleMeshNormals, AreAreaWeighted) {
  // Two triangles meet at vertex 0: one in the XY plane (normal +Z) of area 2 and one in the YZ
  // plane (normal +X) of area 1/2; the vertex normal is the area-weighted mean of the two.
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0, 0, 1}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 4, 3}};
  m.compute_vertex_normals();
  const vec3 expected = glm::normalize(2.0f * vec3(0, 0, 1) + 0.5f * vec3(1, 0, 0));
  EXPECT_LT(glm::length(m.normals[0] - expected), 1e-6f);
  EXPECT_LT(glm::length(m.normals[1] - vec3(0, 0, 1)), 1e-6f);
  EXPECT_LT(glm::length(m.normals[3] - vec3(1, 0, 0)), 1e-6f);
}

TEST(TriangleMeshNormals, HandleDegenerateTriangles) {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0},  // a proper triangle, normal +Z
                 {5, 5, 5}, {6, 6, 6}, {7, 7, 7},  // collinear: zero area
                 {9, 0, 0},                        // repeated index: zero area
                 {3, 3, 3}};                       // used by no triangle
  m.triangles = {{0, 1, 2}, {3, 4, 5}, {6, 6, 1}, {0, 0, 0}};
  m.compute_vertex_normals();
  ASSERT_EQ(m.normals.size(), m.positions.size());
  for (std::size_t i = 0; i < m.normals.size(); ++i) {
    EXPECT_TRUE(std::isfinite(m.normals[i].x) && std::isfinite(m.normals[i].y) &&
                std::isfinite(m.normals[i].z))
        << "vertex " << i;
    EXPECT_NEAR(glm::length(m.normals[i]), 1.0f, 1e-6f) << "vertex " << i;
  }
  // Degenerate triangles add nothing: vertices 0 and 1 keep the proper triangle's normal.
  for (const std::size_t i : {0u, 1u, 2u}) EXPECT_LT(glm::length(m.normals[i] - vec3(0, 0, 1)), 1e-6f);
  // Vertices that touch only degenerate triangles (or none) get the documented fallback, +Z.
  for (const std::size_t i : {3u, 4u, 5u, 6u, 7u}) EXPECT_EQ(m.normals[i], vec3(0, 0, 1)) << "vertex " << i;
}

TEST(TriangleMeshNormals, OppositeTrianglesCancelToTheFallback) {
  // The same triangle both ways round: the two face normals cancel exactly.
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 1}};
  m.compute_vertex_normals();
  for (const vec3& n : m.normals) EXPECT_EQ(n, vec3(0, 0, 1));
}

// --- bounds ---------------------------------------------------------------------------------

TEST(TriangleMeshBounds, EncloseExactlyThePositions) {
  std::mt19937 rng(77u);
  std::uniform_real_distribution<float> coordinate(-100.0f, 100.0f);
  for (int trial = 0; trial < 10; ++trial) {
    TriangleMesh m;
    for (int i = 0; i < 50; ++i) m.positions.emplace_back(coordinate(rng), coordinate(rng), coordinate(rng));
    const specula::Aabb box = m.bounds();
    ASSERT_FALSE(box.empty());
    for (int axis = 0; axis < 3; ++axis) {
      float lo = std::numeric_limits<float>::infinity(), hi = -lo;
      for (const vec3& p : m.positions) {
        EXPECT_TRUE(p[axis] >= box.min[axis] && p[axis] <= box.max[axis]);
        lo = std::min(lo, p[axis]);
        hi = std::max(hi, p[axis]);
      }
      EXPECT_EQ(box.min[axis], lo) << "tight: the minimum is a vertex coordinate";
      EXPECT_EQ(box.max[axis], hi);
    }
  }
  EXPECT_TRUE(TriangleMesh{}.bounds().empty()) << "no positions, empty box";
  TriangleMesh one;
  one.positions = {vec3(1, 2, 3)};
  EXPECT_EQ(one.bounds().min, vec3(1, 2, 3));
  EXPECT_EQ(one.bounds().max, vec3(1, 2, 3));
  EXPECT_FALSE(one.bounds().empty());
}

} // namespace
