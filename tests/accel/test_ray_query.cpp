// The triangle tests and the box test every native structure shares (engine/accel/common).
#include "specula/accel/common/ray_query.h"
#include "specula/accel/common/simd_lanes.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
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

namespace {

/// Float arrays compared bit for bit.
bool same_bits(float a, float b) {
  return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b);
}
bool same_bits(const vec3& a, const vec3& b) {
  return same_bits(a.x, b.x) && same_bits(a.y, b.y) && same_bits(a.z, b.z);
}

/// prepare_coherent_lanes of one width against PreparedRay::make, valid() and intersect_box lane
/// by lane, over seeded packets with hard lanes. Returns how many packets took the vector path
/// with more than one lane.
template <int N, class Lanes, class Prepare>
int check_vector_prepared_lanes(Prepare prepare, std::uint32_t seed, int& failures) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  int vector_packets = 0;
  for (int packet = 0; packet < 20000; ++packet) {
    // Most packets fan out around one direction from one eye (camera-like); some lanes are made
    // hard: NaN or infinite components, zero or signed-zero directions, empty intervals.
    const vec3 eye = 4.0f * vec3(unit(rng), unit(rng), unit(rng));
    const vec3 base(unit(rng), unit(rng), unit(rng));
    const float spread = packet % 3 == 0 ? 1.0f : 0.05f;
    RayPacket<N> p;
    bool active[N];
    for (int i = 0; i < N; ++i) {
      vec3 d = base + spread * vec3(unit(rng), unit(rng), unit(rng));
      vec3 o = eye;
      float tnear = 0.0f, tfar = kInf;
      switch (rng() % 24) {
      case 0:
        d[rng() % 3] = nan;
        break;
      case 1:
        d[rng() % 3] = -kInf;
        break;
      case 2:
        o[rng() % 3] = kInf;
        break;
      case 3:
        d = vec3(0.0f);
        break;
      case 4:
        d = vec3(-0.0f, 0.0f, -0.0f);
        break;
      case 5:
        d[rng() % 3] = -0.0f;
        break;
      case 6:
        d[rng() % 3] = 0.0f;
        break;
      case 7:
        tnear = 2.0f, tfar = 1.0f;
        break;
      case 8:
        tnear = -1.0f;
        break;
      case 9:
        tfar = nan;
        break;
      case 10:
        tnear = kInf;
        break;
      case 11:
        tfar = 0.5f + 10.0f * unit(rng);
        break;
      case 12:
        d = vec3(d.x, d.x, d.z);
        break; // a tie for the dominant axis
      default:
        break;
      }
      p.ox[i] = o.x, p.oy[i] = o.y, p.oz[i] = o.z;
      p.dx[i] = d.x, p.dy[i] = d.y, p.dz[i] = d.z;
      p.tnear[i] = tnear, p.tfar[i] = tfar;
      active[i] = rng() % 6 != 0;
    }
    const Aabb box{vec3(-1.0f) + 0.5f * vec3(unit(rng), unit(rng), unit(rng)),
                   vec3(1.0f) + 0.5f * vec3(unit(rng), unit(rng), unit(rng))};
    const Aabb* with_box = packet % 4 == 0 ? nullptr : &box;

    // The reference, lane by lane.
    PreparedRay want[N];
    float want_tmin[N], want_tmax[N];
    unsigned want_mask = 0, live = 0;
    for (int i = 0; i < N; ++i) {
      want[i] = PreparedRay::make(vec3(p.ox[i], p.oy[i], p.oz[i]), vec3(p.dx[i], p.dy[i], p.dz[i]),
                                  p.tnear[i], p.tfar[i]);
      if (!active[i] || !want[i].valid()) continue;
      live |= 1u << i;
      if (with_box == nullptr ||
          intersect_box(want[i], box.min, box.max, want_tmin[i], want_tmax[i]))
        want_mask |= 1u << i;
    }
    bool agree = true;
    for (unsigned m = live; m; m &= m - 1) {
      const PreparedRay& a = want[std::countr_zero(live)];
      const PreparedRay& b = want[std::countr_zero(m)];
      agree = agree && a.kx == b.kx && a.ky == b.ky && a.kz == b.kz && a.neg[0] == b.neg[0] &&
              a.neg[1] == b.neg[1] && a.neg[2] == b.neg[2];
    }

    PreparedRay got[N];
    alignas(32) float tmin[N], tmax[N];
    unsigned mask = 0;
    std::uint32_t neg[3] = {9, 9, 9};
    Lanes w;
    const bool vector = prepare(p, active, with_box, got, tmin, tmax, mask, neg, w);
    if (vector != agree) {
      if (++failures <= 5)
        ADD_FAILURE() << "packet " << packet << ": vector path " << vector << ", lanes agree "
                      << agree;
      continue;
    }
    if (!vector) continue;
    if (std::popcount(mask) > 1) ++vector_packets;
    bool ok = mask == want_mask;
    alignas(32) float org[3][N], inv[3][N], sx[N], sy[N], sz[N], tn[N];
    for (int a = 0; a < 3; ++a) {
      std::memcpy(org[a], &w.org[a], sizeof(org[a]));
      std::memcpy(inv[a], &w.inv[a], sizeof(inv[a]));
    }
    std::memcpy(sx, &w.sx, sizeof(sx));
    std::memcpy(sy, &w.sy, sizeof(sy));
    std::memcpy(sz, &w.sz, sizeof(sz));
    std::memcpy(tn, &w.tnear, sizeof(tn));
    for (unsigned m = mask & want_mask; m; m &= m - 1) {
      const int i = std::countr_zero(m);
      const PreparedRay& a = got[i];
      const PreparedRay& b = want[i];
      ok = ok && same_bits(a.org, b.org) && same_bits(a.dir, b.dir) &&
           same_bits(a.inv_dir, b.inv_dir) && same_bits(a.tnear, b.tnear) &&
           same_bits(a.tfar, b.tfar) && a.kx == b.kx && a.ky == b.ky && a.kz == b.kz &&
           same_bits(a.sx, b.sx) && same_bits(a.sy, b.sy) && same_bits(a.sz, b.sz);
      for (int k = 0; k < 3; ++k) {
        ok = ok && a.neg[k] == b.neg[k] && neg[k] == b.neg[k];
        ok = ok && same_bits(org[k][i], b.org[k]) && same_bits(inv[k][i], b.inv_dir[k]);
      }
      ok = ok && same_bits(sx[i], b.sx) && same_bits(sy[i], b.sy) && same_bits(sz[i], b.sz) &&
           same_bits(tn[i], b.tnear) && w.kx == b.kx && w.ky == b.ky && w.kz == b.kz;
      if (with_box != nullptr)
        ok = ok && same_bits(tmin[i], want_tmin[i]) && same_bits(tmax[i], want_tmax[i]);
    }
    if (!ok && ++failures <= 5)
      ADD_FAILURE() << "packet " << packet << " of " << N << " lanes: mask " << mask << " (want "
                    << want_mask << ") or a lane's fields differ from PreparedRay::make";
  }
  return vector_packets;
}

} // namespace

// The packet kernels' vector preparation (simd_lanes.h) must give every lane the bits the
// single-ray path gives it, and must take the packets whose lanes agree (signs, ray space).
TEST(RayQuery, VectorPreparedLanesEqualPreparedRayMakeBitForBit) {
  int failures = 0;
  const int sse = check_vector_prepared_lanes<4, simd_sse::WatertightLanes>(
      [](auto&&... a) { return simd_sse::prepare_coherent_lanes(a...); }, 17, failures);
  EXPECT_GT(sse, 1000);
  if (cpu_has_avx2()) {
    const int avx2 = check_vector_prepared_lanes<8, simd_avx2::WatertightLanes>(
        [](auto&&... a) { return simd_avx2::prepare_coherent_lanes(a...); }, 19, failures);
    EXPECT_GT(avx2, 1000);
  }
  EXPECT_EQ(failures, 0);
}
