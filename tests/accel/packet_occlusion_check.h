#pragma once
// The occlusion packets' check shared by the structures' tests (WideBvh, KdTree): occluded4 /
// occluded8 against the same tree's single-ray occluded().

#include "specula/accel/common/ray_query.h"
#include "specula/accel/common/simd_lanes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

namespace specula::accel::test {

/// Packets of N shadow-like rays against the same tree's single-ray occlusion: lane by lane the
/// same answer. Each packet leaves a small patch beside the mesh for
/// points inside its box, so that most packets share their signs and ray space and take the
/// packet walk, half of them aimed at a vertex or an edge's midpoint; tfar is each ray's own first
/// hit, an ulp either side of it, a fraction of it or infinite; some lanes are reversed,
/// untraceable (zero direction, NaN origin, an empty interval) or inactive. Counts the lanes
/// blocked and clear and the packets that walked as one.
template <int N, class Tree>
int occlusion_mismatches(const Tree& tree, const TriangleView& view, const Aabb& box,
                         TriangleTest test, std::uint32_t seed, int& blocked,
                         int& clear, int& coherent) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const vec3 c = box.center();
  const float radius = glm::length(box.extent()) * 0.5f + 1e-3f;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  int bad = 0;
  for (int packet = 0; packet < 1500; ++packet) {
    const vec3 patch =
        c + radius * vec3(3.0f * u01(rng) - 1.5f, 1.6f + u01(rng), 3.0f * u01(rng) - 1.5f);
    // A quarter of the packets start on one vertex's coordinate plane: a split plane of the
    // kd-tree, the plane of an axis-aligned face (hits within rounding of the origin must be
    // answered as the single ray answers them).
    const int on_axis = rng() % 4 == 0 ? int(rng() % 3) : -1;
    const float on_plane =
        view.vertex(std::uint32_t(rng() % view.count), int(rng() % 3))[std::max(on_axis, 0)];
    const bool away = rng() % 2 == 0; // leaving the plane outwards, as from a box's face
    RayPacket<N> p;
    bool active[N];
    for (int i = 0; i < N; ++i) {
      const vec3 o = patch + 0.05f * radius * vec3(u01(rng), u01(rng), u01(rng));
      vec3 target = box.min + box.extent() * vec3(u01(rng), u01(rng), u01(rng));
      if (rng() % 2 == 0) {
        // At a vertex or an edge's midpoint: edge functions of exactly 0 (the scalar fallback).
        const auto t = std::uint32_t(rng() % view.count);
        const int k = int(rng() % 3);
        const vec3 a = view.vertex(t, k), b = view.vertex(t, (k + 1) % 3);
        target = rng() % 2 == 0 ? a : 0.5f * (a + b);
      }
      vec3 d = target - o;
      PreparedRay first = PreparedRay::make(o, d, 0.0f, kInf);
      TriangleHit h;
      tree.intersect(first, h);
      float tnear = 0.0f, tfar = kInf;
      const float reach = h.hit() ? h.t : 1.0f;
      switch (rng() % 6) {
      case 0:
        tfar = reach;
        break;
      case 1:
        tfar = std::nextafter(reach, 0.0f);
        break;
      case 2:
        tfar = std::nextafter(reach, kInf);
        break;
      case 3:
        tfar = reach * u01(rng);
        break;
      case 4:
        tfar = 2.0f * reach;
        break;
      default:
        break;
      }
      vec3 origin = o;
      if (on_axis >= 0) {
        origin[on_axis] = on_plane;
        d = away ? origin - target : target - origin;
      }
      switch (rng() % 24) {
      case 0:
        d = -d;
        break; // mixed signs
      case 1:
        d = vec3(0.0f);
        break; // untraceable
      case 2:
        origin.x = nan;
        break; // untraceable
      case 3:
        tnear = tfar = 0.5f * reach;
        break; // empty interval: (t, t)
      case 4:
        tnear = 0.5f * reach;
        break;
      default:
        break;
      }
      p.ox[i] = origin.x, p.oy[i] = origin.y, p.oz[i] = origin.z;
      p.dx[i] = d.x, p.dy[i] = d.y, p.dz[i] = d.z;
      p.tnear[i] = tnear, p.tfar[i] = tfar;
      active[i] = rng() % 9 != 0;
    }
    // Whether this packet walks as one: the lanes' preparation agrees and more than one is live.
    {
      PreparedRay prepared[N];
      unsigned mask = 0;
      std::uint32_t neg[3];
      bool together = false;
      if constexpr (N == 4) {
        simd_sse::WatertightLanes w;
        together = simd_sse::prepare_coherent_lanes(p, active, nullptr, prepared, nullptr, nullptr,
                                                    mask, neg, w);
      } else if (cpu_has_avx2()) {
        simd_avx2::WatertightLanes w;
        together = simd_avx2::prepare_coherent_lanes(p, active, nullptr, prepared, nullptr, nullptr,
                                                     mask, neg, w);
      }
      if (together && std::popcount(mask) > 1 && test == TriangleTest::watertight) ++coherent;
    }
    unsigned got;
    if constexpr (N == 4)
      got = tree.occluded4(p, active, test);
    else
      got = tree.occluded8(p, active, test);
    for (int i = 0; i < N; ++i) {
      const PreparedRay r = PreparedRay::make(
          vec3(p.ox[i], p.oy[i], p.oz[i]), vec3(p.dx[i], p.dy[i], p.dz[i]), p.tnear[i], p.tfar[i]);
      const bool want = active[i] && r.valid() && tree.occluded(r, test);
      const bool lane = ((got >> i) & 1u) != 0;
      (want ? blocked : clear) += active[i] ? 1 : 0;
      if (lane != want && ++bad <= 3)
        ADD_FAILURE() << "N=" << N << " packet " << packet << " lane " << i << ": packet says "
                      << lane << ", the single ray " << want;
    }
    if ((got >> N) != 0 && ++bad <= 3) ADD_FAILURE() << "a lane past the packet is set";
  }
  return bad;
}

/// Both widths and both triangle tests of `tree` over one mesh (`box`: its finite bounds): no lane
/// disagrees, both answers are common, and most packets walk as one (else only the lane-by-lane
/// walk would be checked).
template <class Tree>
void expect_occlusion_packets_match(const Tree& tree, const TriangleView& view, const Aabb& box,
                                    std::uint32_t seed) {
  int bad = 0, blocked = 0, clear = 0, coherent4 = 0, coherent8 = 0;
  for (TriangleTest test : {TriangleTest::watertight, TriangleTest::moller_trumbore}) {
    bad += occlusion_mismatches<4>(tree, view, box, test, seed, blocked, clear, coherent4);
    bad += occlusion_mismatches<8>(tree, view, box, test, seed + 1, blocked, clear, coherent8);
  }
  EXPECT_EQ(bad, 0);
  EXPECT_GT(blocked, 1000);
  EXPECT_GT(clear, 1000);
  EXPECT_GT(coherent4, 400);
  if (cpu_has_avx2()) {
    EXPECT_GT(coherent8, 100);
  }
}

} // namespace specula::accel::test
