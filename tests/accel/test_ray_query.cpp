// The triangle tests and the box test every native structure shares (engine/accel/common).
#include "specula/accel/common/ray_query.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

using namespace specula;
using namespace specula::accel;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

template <TriangleTest Test>
int hits_on_fan(const PreparedRay& r, const std::vector<vec3>& ring, const vec3& centre) {
  int count = 0;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    float t, u, v;
    count += intersect_triangle<Test>(r, centre, ring[i], ring[(i + 1) % ring.size()], kInf, t, u,
                                      v);
  }
  return count;
}

} // namespace

TEST(RayQuery, BarycentricsFollowEmbreesConvention) {
  const vec3 p0(0, 0, 0), p1(1, 0, 0), p2(0, 1, 0);
  const PreparedRay r = PreparedRay::make(vec3(0.2f, 0.3f, 1.0f), vec3(0, 0, -1), 0.0f, kInf);
  float t, u, v;
  ASSERT_TRUE(intersect_watertight(r, p0, p1, p2, kInf, t, u, v));
  EXPECT_FLOAT_EQ(t, 1.0f);
  EXPECT_NEAR(u, 0.2f, 1e-6f); // weight of p1
  EXPECT_NEAR(v, 0.3f, 1e-6f); // weight of p2
  ASSERT_TRUE(intersect_moller_trumbore(r, p0, p1, p2, kInf, t, u, v));
  EXPECT_NEAR(u, 0.2f, 1e-6f);
  EXPECT_NEAR(v, 0.3f, 1e-6f);
}

TEST(RayQuery, BothWindingsHitAndIntervalIsExclusive) {
  const vec3 p0(0, 0, 0), p1(1, 0, 0), p2(0, 1, 0);
  const PreparedRay down = PreparedRay::make(vec3(0.25f, 0.25f, 2.0f), vec3(0, 0, -1), 0.0f, kInf);
  const PreparedRay up = PreparedRay::make(vec3(0.25f, 0.25f, -2.0f), vec3(0, 0, 1), 0.0f, kInf);
  float t, u, v;
  EXPECT_TRUE(intersect_watertight(down, p0, p1, p2, kInf, t, u, v));
  EXPECT_TRUE(intersect_watertight(up, p0, p1, p2, kInf, t, u, v));
  EXPECT_TRUE(intersect_watertight(down, p0, p2, p1, kInf, t, u, v));
  EXPECT_FALSE(intersect_watertight(down, p0, p1, p2, 2.0f, t, u, v)); // t == tmax: excluded
  const PreparedRay late = PreparedRay::make(vec3(0.25f, 0.25f, 2.0f), vec3(0, 0, -1), 2.0f, kInf);
  EXPECT_FALSE(intersect_watertight(late, p0, p1, p2, kInf, t, u, v)); // t == tnear: excluded
  const PreparedRay away = PreparedRay::make(vec3(0.25f, 0.25f, 2.0f), vec3(0, 0, 1), 0.0f, kInf);
  EXPECT_FALSE(intersect_watertight(away, p0, p1, p2, kInf, t, u, v));
}

// A fan of triangles around a shared vertex, rays aimed exactly at the shared vertex and along the
// shared edges from many directions: the watertight test never lets one through.
TEST(RayQuery, WatertightTestNeverLeaksThroughSharedEdgesOrVertices) {
  std::mt19937 rng(20131);
  std::uniform_real_distribution<float> angle(0.0f, 6.2831853f);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  int leaks = 0, rays = 0;
  for (int fan = 0; fan < 200; ++fan) {
    const vec3 centre(unit(rng) * 100.0f, unit(rng) * 100.0f, unit(rng) * 0.001f);
    std::vector<vec3> ring;
    const int n = 3 + fan % 9;
    const float phase = angle(rng);
    for (int i = 0; i < n; ++i) {
      const float a = phase + 6.2831853f * float(i) / float(n);
      ring.push_back(centre + vec3(std::cos(a), std::sin(a), 0.01f * unit(rng)) * (1.0f + unit(rng) * 0.5f));
    }
    for (int k = 0; k < 20; ++k) {
      const vec3 from = centre + vec3(unit(rng), unit(rng), 1.0f + std::abs(unit(rng))) * 3.0f;
      // At the shared vertex, and at points exactly on the shared edges.
      std::vector<vec3> targets = {centre};
      for (const vec3& p : ring) targets.push_back(centre + (p - centre) * 0.5f);
      for (const vec3& target : targets) {
        const PreparedRay r = PreparedRay::make(from, target - from, 0.0f, kInf);
        ++rays;
        leaks += hits_on_fan<TriangleTest::watertight>(r, ring, centre) == 0;
      }
    }
  }
  EXPECT_EQ(leaks, 0) << "of " << rays << " rays";
}

TEST(RayQuery, InvalidRaysAreRecognised) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(PreparedRay::make(vec3(0), vec3(0, 0, 1), 0.0f, kInf).valid());
  EXPECT_FALSE(PreparedRay::make(vec3(nan, 0, 0), vec3(0, 0, 1), 0.0f, kInf).valid());
  EXPECT_FALSE(PreparedRay::make(vec3(0), vec3(0, kInf, 1), 0.0f, kInf).valid());
  EXPECT_FALSE(PreparedRay::make(vec3(0), vec3(0, 0, 0), 0.0f, kInf).valid());
  EXPECT_FALSE(PreparedRay::make(vec3(0), vec3(0, 0, 1), nan, kInf).valid());
  EXPECT_FALSE(PreparedRay::make(vec3(0), vec3(0, 0, 1), 2.0f, 1.0f).valid());
}

TEST(RayQuery, BoxTestIsConservativeForHitsOnTheBoxFaces) {
  // Triangles lying exactly on a box face are hit by rays the box test must therefore pass, from
  // far away and at grazing angles.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const vec3 lo(-1e5f + 0.3f, 2.0f, 7.0f), hi(-1e5f + 1.7f, 2.5f, 9.0f);
  int culled = 0;
  for (int i = 0; i < 100000; ++i) {
    // A point on the face x = hi.x, a ray from far away towards it.
    const vec3 p(hi.x, lo.y + unit(rng) * (hi.y - lo.y), lo.z + unit(rng) * (hi.z - lo.z));
    const vec3 from = p + vec3(1.0f + unit(rng) * 1e4f, (unit(rng) - 0.5f) * 1e4f, (unit(rng) - 0.5f) * 1e4f);
    const PreparedRay r = PreparedRay::make(from, p - from, 0.0f, kInf);
    float t0, t1;
    culled += !intersect_box(r, lo, hi, t0, t1);
  }
  EXPECT_EQ(culled, 0);
}

TEST(RayQuery, EightRayPacketsRunAsTwoPacketsOfFourLaneForLane) {
  RayPacket<8> rays;
  PacketHits<8> hits;
  hits.clear();
  bool active[8];
  for (int i = 0; i < 8; ++i) {
    rays.ox[i] = float(i);
    rays.oy[i] = rays.oz[i] = 0.0f;
    rays.dx[i] = rays.dy[i] = 0.0f;
    rays.dz[i] = 1.0f;
    rays.tnear[i] = 0.0f;
    rays.tfar[i] = 100.0f;
    active[i] = i % 3 != 0;
  }
  int calls = 0;
  // A stand-in for a 4-wide kernel: each active lane "hits" at t = 10 + its origin's x.
  as_two_packets_of_4(rays, hits, active, [&](RayPacket<4>& r4, PacketHits<4>& h4, const bool* a4) {
    ++calls;
    for (int i = 0; i < 4; ++i) {
      if (!a4[i]) continue;
      r4.tfar[i] = 10.0f + r4.ox[i];
      h4.set(i, TriangleHit{r4.tfar[i], 0.25f, 0.5f, std::uint32_t(r4.ox[i])});
    }
  });
  EXPECT_EQ(calls, 2);
  for (int i = 0; i < 8; ++i) {
    if (active[i]) {
      EXPECT_EQ(hits.prim[i], std::uint32_t(i));
      EXPECT_FLOAT_EQ(hits.t[i], 10.0f + float(i));
      EXPECT_FLOAT_EQ(rays.tfar[i], 10.0f + float(i));
      EXPECT_FLOAT_EQ(hits.v[i], 0.5f);
    } else {
      EXPECT_EQ(hits.prim[i], 0xFFFFFFFFu);
      EXPECT_FLOAT_EQ(rays.tfar[i], 100.0f);
    }
  }
}
