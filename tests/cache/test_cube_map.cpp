// Cube-map addressing of the ray-cache cubes: the OpenGL table (eq. 5 of the paper), round trips
// through every texel of every face, and the edges and corners where faces meet.

#include "specula/cache/cube_map.h"

#include <gtest/gtest.h>

#include <random>

namespace specula::cache {
namespace {

struct TableRow {
  vec3 major;    // the major axis direction
  vec3 sc_axis;  // direction whose component is +sc
  vec3 tc_axis;  // direction whose component is +tc
  std::uint32_t face;
};

// OpenGL 4.6 core profile, table 8.19: major axis, then sc and tc as signed components of r.
const TableRow kTable[] = {
    {vec3(1, 0, 0), vec3(0, 0, -1), vec3(0, -1, 0), 0},  // +rx: sc = -rz, tc = -ry
    {vec3(-1, 0, 0), vec3(0, 0, 1), vec3(0, -1, 0), 1},  // -rx: sc = +rz, tc = -ry
    {vec3(0, 1, 0), vec3(1, 0, 0), vec3(0, 0, 1), 2},    // +ry: sc = +rx, tc = +rz
    {vec3(0, -1, 0), vec3(1, 0, 0), vec3(0, 0, -1), 3},  // -ry: sc = +rx, tc = -rz
    {vec3(0, 0, 1), vec3(1, 0, 0), vec3(0, -1, 0), 4},   // +rz: sc = +rx, tc = -ry
    {vec3(0, 0, -1), vec3(-1, 0, 0), vec3(0, -1, 0), 5}, // -rz: sc = -rx, tc = -ry
};

TEST(CubeMap, AgreesWithTheOpenGLTable) {
  for (const TableRow& row : kTable) {
    for (const float sc : {-0.9f, -0.5f, 0.0f, 0.3f, 0.8f}) {
      for (const float tc : {-0.7f, 0.0f, 0.45f, 0.95f}) {
        const float ma = 2.5f; // any length: the coordinates divide by |m|
        const vec3 r = ma * row.major + (sc * ma) * row.sc_axis + (tc * ma) * row.tc_axis;
        const CubeCoord c = cube_coord(r);
        EXPECT_EQ(c.face, row.face) << r.x << " " << r.y << " " << r.z;
        EXPECT_NEAR(c.u, 0.5f * (sc + 1.0f), 1e-6f);
        EXPECT_NEAR(c.v, 0.5f * (tc + 1.0f), 1e-6f);
      }
    }
  }
}

TEST(CubeMap, EveryTexelOfEveryFaceRoundTrips) {
  for (const std::uint32_t res : {1u, 2u, 3u, 16u, 64u, 128u}) {
    for (std::uint32_t i = 0; i < kFaceCount * res * res; ++i) {
      const vec3 d = texel_direction(i, res);
      ASSERT_NEAR(glm::length(d), 1.0f, 1e-6f);
      ASSERT_EQ(texel_of(d, res), i) << "resolution " << res << " texel " << i;
    }
  }
}

TEST(CubeMap, DirectionAndCoordinatesInvertEachOther) {
  std::mt19937 rng(20131015u);
  std::normal_distribution<float> n(0.0f, 1.0f);
  for (int k = 0; k < 10000; ++k) {
    const vec3 s = glm::normalize(vec3(n(rng), n(rng), n(rng)));
    const CubeCoord c = cube_coord(s);
    ASSERT_GE(c.u, 0.0f);
    ASSERT_LE(c.u, 1.0f);
    ASSERT_GE(c.v, 0.0f);
    ASSERT_LE(c.v, 1.0f);
    const vec3 back = glm::normalize(cube_direction(c.face, c.u, c.v));
    ASSERT_NEAR(glm::dot(back, s), 1.0f, 1e-5f);
  }
}

TEST(CubeMap, EdgesAndCornersLandOnAFaceThatHoldsThem) {
  // Every direction whose components tie in magnitude: edges (two tie) and corners (three).
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z) {
        if (x == 0 && y == 0 && z == 0) continue;
        const vec3 s{float(x), float(y), float(z)};
        const CubeCoord c = cube_coord(s);
        // The face's major axis is one of the largest components (ties: x before y before z).
        const int axis = int(c.face / 2);
        const float major = s[axis];
        EXPECT_EQ(std::abs(major), 1.0f) << x << y << z;
        EXPECT_EQ(c.face % 2 == 0, major > 0.0f);
        for (int a = 0; a < axis; ++a) EXPECT_LT(std::abs(s[a]), 1.0f) << "tie goes to x, then y";
        // On an edge the texture coordinate is exactly 0, ½ or 1, and the texel is in range.
        for (const float t : {c.u, c.v})
          EXPECT_TRUE(t == 0.0f || t == 0.5f || t == 1.0f) << x << y << z << " " << t;
        for (const std::uint32_t res : {1u, 8u, 512u})
          EXPECT_LT(texel_of(s, res), kFaceCount * res * res);
        // Nudged off the edge towards each tied face, the direction is addressed by that face.
        for (int a = 0; a < 3; ++a) {
          if (std::abs(s[a]) != 1.0f) continue;
          vec3 nudged = s;
          nudged[a] *= 1.001f;
          EXPECT_EQ(cube_coord(nudged).face, std::uint32_t(2 * a + (s[a] > 0.0f ? 0 : 1)));
        }
      }
}

TEST(CubeMap, NeighbouringTexelsAcrossAFaceEdgeAreNeighbouringDirections) {
  // Seams: the last texel column of one face and the first of the next face it touches are a
  // texel apart in angle, not across the cube.
  const std::uint32_t res = 64;
  const float texel = 2.0f / float(res);
  for (std::uint32_t i = 0; i < kFaceCount * res * res; ++i) {
    const vec3 d = texel_direction(i, res);
    // A step of under half a texel in any direction stays within a texel's angle.
    for (const vec3& step : {vec3(1, 0, 0), vec3(0, 1, 0), vec3(0, 0, 1)}) {
      const vec3 moved = glm::normalize(d + 0.4f * texel * step);
      const vec3 there = texel_direction(texel_of(moved, res), res);
      ASSERT_GT(glm::dot(there, moved), std::cos(2.0f * texel_half_angle(res))) << i;
    }
  }
}

} // namespace
} // namespace specula::cache
