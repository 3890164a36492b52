#include "specula/accel/bvh/wide_bvh.h"

#include "specula/accel/common/simd_lanes.h"

#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <limits>
#include <stdexcept>
#include <type_traits>

namespace specula::accel {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

[[nodiscard]] float half_area(const gpu::BvhNode& n) {
  const vec3 e = n.bounds_max - n.bounds_min;
  return e.x * e.y + e.y * e.z + e.z * e.x;
}

WideBvhNode empty_node() {
  WideBvhNode w;
  for (int a = 0; a < 3; ++a)
    for (int i = 0; i < 4; ++i) {
      w.lo[a][i] = kInf;
      w.hi[a][i] = -kInf;
    }
  for (int i = 0; i < 4; ++i) w.child[i] = w.count[i] = 0;
  return w;
}

/// Appends the triangles of a binary leaf (entries [first, first + count) of `indices`) as groups
/// of four; returns the first group.
std::uint32_t append_groups(const TriangleView& tris, std::span<const std::uint32_t> indices,
                            std::uint32_t first, std::uint32_t count,
                            std::vector<WideTriangles>& groups) {
  const auto start = std::uint32_t(groups.size());
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  for (std::uint32_t k = 0; k < count; k += 4) {
    WideTriangles g;
    for (int lane = 0; lane < 4; ++lane) {
      const bool used = k + std::uint32_t(lane) < count;
      const std::uint32_t prim = used ? indices[first + k + std::uint32_t(lane)] : 0xFFFFFFFFu;
      g.prim[lane] = prim;
      for (int v = 0; v < 3; ++v)
        for (int a = 0; a < 3; ++a) g.p[v][a][lane] = used ? tris.vertex(prim, v)[a] : kNaN;
    }
    groups.push_back(g);
  }
  return start;
}

struct Collapse {
  std::span<const gpu::BvhNode> bn;
  std::span<const std::uint32_t> indices;
  const TriangleView& tris;
  std::vector<WideBvhNode>& out;
  std::vector<WideTriangles>& groups;
  WideBvhStats& stats;
};

/// Appends the wide node over binary node `b` (its children, opened down to at most four) and,
/// depth first, the wide nodes under it; returns its index.
std::uint32_t collapse(const Collapse& c, std::uint32_t b, std::uint32_t depth) {
  const std::span<const gpu::BvhNode> bn = c.bn;
  std::vector<WideBvhNode>& out = c.out;
  WideBvhStats& stats = c.stats;
  std::uint32_t kids[4];
  int n = 0;
  if ((bn[b].count & ~gpu::kBvhUnbuilt) != 0) {
    kids[n++] = b; // a tree that is one leaf
  } else {
    kids[n++] = bn[b].index;
    kids[n++] = bn[b].index + 1;
    while (n < 4) {
      int open = -1;
      float largest = -kInf;
      for (int i = 0; i < n; ++i) {
        const gpu::BvhNode& k = bn[kids[i]];
        if (k.count != 0) continue;
        const float area = half_area(k);
        if (open < 0 || area > largest) {
          open = i;
          largest = area;
        }
      }
      if (open < 0) break;
      const std::uint32_t first = bn[kids[open]].index;
      kids[open] = first;
      kids[n++] = first + 1;
    }
  }
  const auto w = std::uint32_t(out.size());
  out.push_back(empty_node());
  stats.max_depth = std::max(stats.max_depth, depth);
  stats.empty_slots += std::uint32_t(4 - n);
  for (int i = 0; i < n; ++i) {
    const gpu::BvhNode& k = bn[kids[i]];
    std::uint32_t child = 0, count = k.count & ~gpu::kBvhUnbuilt;
    if (count != 0) {
      child = append_groups(c.tris, c.indices, k.index, count, c.groups);
      stats.triangles += count;
      count = (count + 3) / 4;
      ++stats.leaves;
    } else {
      child = collapse(c, kids[i], depth + 1);
    }
    WideBvhNode& node = out[w]; // after the recursion: `out` may have moved
    for (int a = 0; a < 3; ++a) {
      node.lo[a][i] = k.bounds_min[a];
      node.hi[a][i] = k.bounds_max[a];
    }
    node.child[i] = child;
    node.count[i] = count;
  }
  return w;
}

/// A ray's constants for the lane-wise triangle test.
struct RayLanes {
  __m128 org[3];
  __m128 sx, sy, sz, tnear;
};

RayLanes ray_lanes(const PreparedRay& r) {
  RayLanes l;
  for (int a = 0; a < 3; ++a) l.org[a] = _mm_set1_ps(r.org[a]);
  l.sx = _mm_set1_ps(r.sx);
  l.sy = _mm_set1_ps(r.sy);
  l.sz = _mm_set1_ps(r.sz);
  l.tnear = _mm_set1_ps(r.tnear);
  return l;
}

/// intersect_watertight (ray_query.h) on the four triangles of `g` at once, every operation the
/// scalar test's in its order (no fused multiply-adds: SSE2 has none), the double-precision
/// fallback lane by lane. Returns the lanes hit within (tnear, tmax), with t, u and v.
unsigned watertight4(const PreparedRay& r, const RayLanes& l, const WideTriangles& g, float tmax,
                     __m128& t_out, __m128& u_out, __m128& v_out) {
  __m128 d[3][3]; // vertex k minus the origin, per axis
  for (int k = 0; k < 3; ++k)
    for (int a = 0; a < 3; ++a) d[k][a] = _mm_sub_ps(_mm_load_ps(g.p[k][a]), l.org[a]);
  const int kx = r.kx, ky = r.ky, kz = r.kz;
  const __m128 ax = _mm_sub_ps(d[0][kx], _mm_mul_ps(l.sx, d[0][kz]));
  const __m128 ay = _mm_sub_ps(d[0][ky], _mm_mul_ps(l.sy, d[0][kz]));
  const __m128 bx = _mm_sub_ps(d[1][kx], _mm_mul_ps(l.sx, d[1][kz]));
  const __m128 by = _mm_sub_ps(d[1][ky], _mm_mul_ps(l.sy, d[1][kz]));
  const __m128 cx = _mm_sub_ps(d[2][kx], _mm_mul_ps(l.sx, d[2][kz]));
  const __m128 cy = _mm_sub_ps(d[2][ky], _mm_mul_ps(l.sy, d[2][kz]));
  __m128 U = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
  __m128 V = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
  __m128 W = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
  const __m128 zero = _mm_setzero_ps();
  const unsigned exact = unsigned(_mm_movemask_ps(
      _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(U, zero), _mm_cmpeq_ps(V, zero)), _mm_cmpeq_ps(W, zero))));
  if (exact != 0) [[unlikely]] {
    alignas(16) float e[9][4];
    const __m128 parts[9] = {ax, ay, bx, by, cx, cy, U, V, W};
    for (int k = 0; k < 9; ++k) _mm_store_ps(e[k], parts[k]);
    for (unsigned m = exact; m != 0; m &= m - 1) {
      const int i = std::countr_zero(m);
      edge_functions_in_double(e[0][i], e[1][i], e[2][i], e[3][i], e[4][i], e[5][i], e[6][i],
                               e[7][i], e[8][i]);
    }
    U = _mm_load_ps(e[6]);
    V = _mm_load_ps(e[7]);
    W = _mm_load_ps(e[8]);
  }
  const __m128 negative =
      _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(U, zero), _mm_cmplt_ps(V, zero)), _mm_cmplt_ps(W, zero));
  const __m128 positive =
      _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(U, zero), _mm_cmpgt_ps(V, zero)), _mm_cmpgt_ps(W, zero));
  const __m128 det = _mm_add_ps(_mm_add_ps(U, V), W);
  const __m128 az = _mm_mul_ps(l.sz, d[0][kz]);
  const __m128 bz = _mm_mul_ps(l.sz, d[1][kz]);
  const __m128 cz = _mm_mul_ps(l.sz, d[2][kz]);
  const __m128 T = _mm_add_ps(_mm_add_ps(_mm_mul_ps(U, az), _mm_mul_ps(V, bz)), _mm_mul_ps(W, cz));
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 abs_det = _mm_andnot_ps(sign, det);
  const __m128 signed_t = _mm_xor_ps(T, _mm_and_ps(det, sign));
  const __m128 tmax4 = _mm_set1_ps(tmax);
  __m128 ok = _mm_andnot_ps(_mm_and_ps(negative, positive), _mm_cmpneq_ps(det, zero));
  ok = _mm_and_ps(ok, _mm_cmpgt_ps(signed_t, _mm_mul_ps(l.tnear, abs_det)));
  ok = _mm_and_ps(ok, _mm_cmplt_ps(signed_t, _mm_mul_ps(tmax4, abs_det)));
  if (_mm_movemask_ps(ok) == 0) return 0;
  const __m128 inv_det = _mm_div_ps(_mm_set1_ps(1.0f), det);
  const __m128 t = _mm_mul_ps(T, inv_det);
  ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpgt_ps(t, l.tnear), _mm_cmplt_ps(t, tmax4)));
  t_out = t;
  u_out = _mm_mul_ps(V, inv_det);
  v_out = _mm_mul_ps(W, inv_det);
  return unsigned(_mm_movemask_ps(ok));
}

vec3 vertex(const WideTriangles& g, int k, int lane) {
  return vec3(g.p[k][0][lane], g.p[k][1][lane], g.p[k][2][lane]);
}

/// The closest hit in a group within (tnear, r.tfar): the lowest t, the first lane on a tie (as
/// the scalar loop, which tests in order against the shrinking tfar, keeps the first).
template <TriangleTest Test>
bool closest_in_group(PreparedRay& r, const RayLanes& l, const WideTriangles& g, TriangleHit& hit) {
  if constexpr (Test == TriangleTest::watertight) {
    __m128 t4, u4, v4;
    const unsigned m = watertight4(r, l, g, r.tfar, t4, u4, v4);
    if (m == 0) return false;
    alignas(16) float t[4], u[4], v[4];
    _mm_store_ps(t, t4);
    _mm_store_ps(u, u4);
    _mm_store_ps(v, v4);
    int best = std::countr_zero(m);
    for (unsigned rest = m & (m - 1); rest != 0; rest &= rest - 1) {
      const int i = std::countr_zero(rest);
      if (t[i] < t[best]) best = i;
    }
    r.tfar = t[best];
    hit = TriangleHit{t[best], u[best], v[best], g.prim[best]};
    return true;
  } else {
    bool found = false;
    for (int i = 0; i < 4 && g.prim[i] != 0xFFFFFFFFu; ++i) {
      float t, u, v;
      if (!intersect_moller_trumbore(r, vertex(g, 0, i), vertex(g, 1, i), vertex(g, 2, i), r.tfar,
                                     t, u, v))
        continue;
      r.tfar = t;
      hit = TriangleHit{t, u, v, g.prim[i]};
      found = true;
    }
    return found;
  }
}

template <TriangleTest Test>
bool any_in_group(const PreparedRay& r, const RayLanes& l, const WideTriangles& g) {
  if constexpr (Test == TriangleTest::watertight) {
    __m128 t4, u4, v4;
    return watertight4(r, l, g, r.tfar, t4, u4, v4) != 0;
  } else {
    for (int i = 0; i < 4 && g.prim[i] != 0xFFFFFFFFu; ++i) {
      float t, u, v;
      if (intersect_moller_trumbore(r, vertex(g, 0, i), vertex(g, 1, i), vertex(g, 2, i), r.tfar, t,
                                    u, v))
        return true;
    }
    return false;
  }
}

} // namespace

void WideBvh::build(const Bvh& binary, const TriangleView& tris) {
  nodes_.clear();
  groups_.clear();
  stats_ = WideBvhStats{};
  if (binary.empty()) return;
  binary.expand_all();
  const std::span<const gpu::BvhNode> bn = binary.nodes();
  collapse(Collapse{bn, binary.indices(), tris, nodes_, groups_, stats_}, 0, 0);
  // Three entries pushed per level at most, one node taken.
  if (3 * (std::size_t(stats_.max_depth) + 1) >= std::size_t(kStackSize))
    throw std::length_error("wide BVH: deeper than its traversal stack");
  stats_.nodes = std::uint32_t(nodes_.size());
  stats_.groups = std::uint32_t(groups_.size());
  stats_.bytes = nodes_.size() * sizeof(WideBvhNode) + groups_.size() * sizeof(WideTriangles);
}

template <TriangleTest Test, bool AnyHit>
bool WideBvh::traverse(PreparedRay& r, TriangleHit* hit, std::uint32_t start_child,
                       std::uint32_t start_count) const {
  if (nodes_.empty() || !r.valid()) return false;
  __m128 org[3], inv[3];
  for (int a = 0; a < 3; ++a) {
    org[a] = _mm_set1_ps(r.org[a]);
    inv[a] = _mm_set1_ps(r.inv_dir[a]);
  }
  const __m128 scale = _mm_set1_ps(kBoxFarScale);
  const __m128 tnear = _mm_set1_ps(r.tnear);
  const RayLanes lanes = ray_lanes(r);

  struct Entry {
    std::uint32_t child, count; ///< as in WideBvhNode: count 0 is an interior node
    float t;                    ///< entry distance
  };
  Entry stack[kStackSize];
  int top = 0;
  Entry cur{start_child, start_count, r.tnear};
  bool found = false;
  const WideBvhNode* nodes = nodes_.data();
  for (;;) {
    if (cur.count == 0) {
      const WideBvhNode& n = nodes[cur.child];
      // intersect_box on four boxes: the same operations in the same order; max/min keep the
      // current bound where a distance is NaN, as the scalar test's comparisons do.
      __m128 t0 = tnear;
      __m128 t1 = _mm_set1_ps(r.tfar);
      for (int a = 0; a < 3; ++a) {
        const __m128 lo = _mm_load_ps(n.lo[a]);
        const __m128 hi = _mm_load_ps(n.hi[a]);
        const __m128 near = r.neg[a] != 0 ? hi : lo;
        const __m128 far = r.neg[a] != 0 ? lo : hi;
        const __m128 tn = _mm_mul_ps(_mm_sub_ps(near, org[a]), inv[a]);
        const __m128 tf = _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(far, org[a]), inv[a]), scale);
        t0 = _mm_max_ps(tn, t0);
        t1 = _mm_min_ps(tf, t1);
      }
      unsigned mask = unsigned(_mm_movemask_ps(_mm_cmple_ps(t0, t1)));
      if (mask != 0) {
        alignas(16) float entry[4];
        _mm_store_ps(entry, t0);
        if constexpr (AnyHit) {
          // Order does not matter: the first child is taken, the others pushed.
          const int first = std::countr_zero(mask);
          mask &= mask - 1;
          for (; mask != 0; mask &= mask - 1) {
            const int i = std::countr_zero(mask);
            stack[top++] = {n.child[i], n.count[i], entry[i]};
          }
          cur = {n.child[first], n.count[first], entry[first]};
        } else if ((mask & (mask - 1)) == 0) {
          // One child (most nodes near the leaves): nothing to order. (Bit tests rather than
          // std::has_single_bit and std::popcount, which without POPCNT in the baseline ISA are
          // library calls, one per node step.)
          const int i = std::countr_zero(mask);
          cur = {n.child[i], n.count[i], entry[i]};
        } else if (const unsigned rest = mask & (mask - 1); (rest & (rest - 1)) == 0) {
          // Two: the nearer first, the lower slot on a tie (as the insertion below orders them).
          const int i = std::countr_zero(mask), j = std::countr_zero(mask & (mask - 1));
          const bool swap = entry[i] > entry[j];
          const int near = swap ? j : i, far = swap ? i : j;
          stack[top++] = {n.child[far], n.count[far], entry[far]};
          cur = {n.child[near], n.count[near], entry[near]};
        } else {
          // Three or four: the slots sorted by entry distance with adjacent exchanges (a bubble
          // network: stable, so ties keep the lower slot first, as an insertion would), by
          // selections rather than branches; the farthest pushed first.
          int order[4];
          int k = 0;
          for (; mask != 0; mask &= mask - 1) order[k++] = std::countr_zero(mask);
          const auto exchange = [&](int a, int b) {
            const int x = order[a], y = order[b];
            const bool swap = entry[x] > entry[y];
            order[a] = swap ? y : x;
            order[b] = swap ? x : y;
          };
          if (k == 3) {
            exchange(0, 1);
            exchange(1, 2);
            exchange(0, 1);
          } else {
            exchange(0, 1);
            exchange(1, 2);
            exchange(2, 3);
            exchange(0, 1);
            exchange(1, 2);
            exchange(0, 1);
          }
          for (int j = k - 1; j > 0; --j)
            stack[top++] = {n.child[order[j]], n.count[order[j]], entry[order[j]]};
          cur = {n.child[order[0]], n.count[order[0]], entry[order[0]]};
        }
        continue;
      }
    } else {
      const WideTriangles* g = groups_.data() + cur.child;
      for (std::uint32_t k = 0; k < cur.count; ++k) {
        if constexpr (AnyHit) {
          if (any_in_group<Test>(r, lanes, g[k])) return true;
        } else {
          found |= closest_in_group<Test>(r, lanes, g[k], *hit);
        }
      }
    }
    // The next pending child the ray still reaches (r.tfar may have shrunk).
    for (;;) {
      if (top == 0) return found;
      cur = stack[--top];
      if (cur.t <= r.tfar) break;
    }
  }
}

// ---- Packets ------------------------------------------------------------------------------------

namespace {

/// One lane's watertight test of one triangle, out of line and compiled for the baseline target
/// like the single-ray path (a packet lane on an edge of the triangle: the double fallback).
[[gnu::noinline]] void closest_triangle_lane(PreparedRay& r, const vec3& p0, const vec3& p1,
                                             const vec3& p2, std::uint32_t prim, TriangleHit& hit) {
  float t, u, v;
  if (!intersect_watertight(r, p0, p1, p2, r.tfar, t, u, v)) return;
  r.tfar = t;
  hit = TriangleHit{t, u, v, prim};
}

/// Whether one lane's ray meets triangle (p0, p1, p2) within its (tnear, tfar), by the watertight
/// test, out of line like closest_triangle_lane (an occlusion lane on an edge of the triangle).
[[gnu::noinline]] bool any_triangle_lane(const PreparedRay& r, const vec3& p0, const vec3& p1,
                                         const vec3& p2) {
  float t, u, v;
  return intersect_watertight(r, p0, p1, p2, r.tfar, t, u, v);
}

} // namespace

// The packet kernel is written once (wide_bvh_packet.inl) over the vector operations of
// simd_lanes.h and compiled twice, for SSE and for AVX2 (chosen at run time).
namespace wide_sse {
namespace {
using namespace simd_sse;
#define SPECULA_SIMD_TARGET
#include "wide_bvh_packet.inl"
#undef SPECULA_SIMD_TARGET
} // namespace
} // namespace wide_sse

namespace wide_avx2 {
namespace {
using namespace simd_avx2;
#define SPECULA_SIMD_TARGET __attribute__((target("avx2")))
#include "wide_bvh_packet.inl"
#undef SPECULA_SIMD_TARGET
} // namespace
} // namespace wide_avx2

namespace {

/// The packet's lanes prepared for one walk (prepare_coherent_lanes); whether they take it: the
/// vector preparation agreed, the test is the watertight one and more than one lane is live
/// (otherwise each lane walks alone).
template <int N, TriangleTest Test>
bool prepare_packet_walk(const RayPacket<N>& rays, const bool* active, PreparedRay* prepared,
                         unsigned& mask, std::uint32_t neg[3], WatertightLanesOf<N>& lanes) {
  const bool vector_prepared = prepare_coherent_lanes<N>(rays, active, nullptr, prepared, nullptr,
                                                         nullptr, mask, neg, lanes);
  return vector_prepared && Test == TriangleTest::watertight && (mask & (mask - 1)) != 0;
}

} // namespace

template <int N, TriangleTest Test>
void WideBvh::intersect_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active,
                               TestTag<Test>) const {
  if (nodes_.empty()) return;
  PreparedRay prepared[N];
  TriangleHit lane_hits[N];
  unsigned mask = 0;
  std::uint32_t neg[3] = {0, 0, 0};
  WatertightLanesOf<N> lanes;
  if (prepare_packet_walk<N, Test>(rays, active, prepared, mask, neg, lanes)) {
    if constexpr (N == 8)
      wide_avx2::traverse_packet(nodes_.data(), groups_.data(), prepared, lane_hits, mask, neg,
                                 lanes);
    else
      wide_sse::traverse_packet(nodes_.data(), groups_.data(), prepared, lane_hits, mask, neg,
                                lanes);
  } else {
    // Lanes that disagree (or the Möller–Trumbore option): each lane's own walk.
    mask = 0;
    for (int i = 0; i < N; ++i) {
      if (!active[i]) continue;
      prepared[i] =
          PreparedRay::make(vec3(rays.ox[i], rays.oy[i], rays.oz[i]),
                            vec3(rays.dx[i], rays.dy[i], rays.dz[i]), rays.tnear[i], rays.tfar[i]);
      if (!prepared[i].valid()) continue;
      mask |= 1u << i;
      traverse<Test, false>(prepared[i], &lane_hits[i]);
    }
  }
  for (unsigned m = mask; m; m &= m - 1) {
    const int i = std::countr_zero(m);
    if (!lane_hits[i].hit()) continue;
    rays.tfar[i] = prepared[i].tfar;
    hits.set(i, lane_hits[i]);
  }
}

void WideBvh::intersect4(RayPacket<4>& rays, PacketHits<4>& hits, const bool active[4],
                         TriangleTest test) const {
  run_packet(rays, hits, active, test, [this](auto&&... a) { intersect_packet(a...); });
}

void WideBvh::intersect8(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                         TriangleTest test) const {
  run_packet(rays, hits, active, test, [this](auto&&... a) { intersect_packet(a...); });
}

template <int N, TriangleTest Test>
unsigned WideBvh::occluded_packet(const RayPacket<N>& rays, const bool* active,
                                  TestTag<Test>) const {
  if (nodes_.empty()) return 0;
  PreparedRay prepared[N];
  unsigned mask = 0;
  std::uint32_t neg[3] = {0, 0, 0};
  WatertightLanesOf<N> lanes;
  if (prepare_packet_walk<N, Test>(rays, active, prepared, mask, neg, lanes)) {
    // A subtree that one lane alone enters is left to that lane's single-ray walk.
    const auto single = [&](int lane, std::uint32_t child, std::uint32_t count) {
      return traverse<TriangleTest::watertight, true>(prepared[lane], nullptr, child, count);
    };
    if constexpr (N == 8)
      return wide_avx2::occlude_packet(nodes_.data(), groups_.data(), prepared, mask, neg, lanes,
                                       single);
    else
      return wide_sse::occlude_packet(nodes_.data(), groups_.data(), prepared, mask, neg, lanes,
                                      single);
  }
  // Lanes that disagree (or the Möller–Trumbore option): each lane's own walk.
  unsigned blocked = 0;
  for (int i = 0; i < N; ++i) {
    if (!active[i]) continue;
    PreparedRay r =
        PreparedRay::make(vec3(rays.ox[i], rays.oy[i], rays.oz[i]),
                          vec3(rays.dx[i], rays.dy[i], rays.dz[i]), rays.tnear[i], rays.tfar[i]);
    if (r.valid() && traverse<Test, true>(r, nullptr)) blocked |= 1u << i;
  }
  return blocked;
}

unsigned WideBvh::occluded4(const RayPacket<4>& rays, const bool active[4],
                            TriangleTest test) const {
  return run_occlusion_packet(rays, active, test,
                              [this](auto&&... a) { return occluded_packet(a...); });
}

unsigned WideBvh::occluded8(const RayPacket<8>& rays, const bool active[8],
                            TriangleTest test) const {
  return run_occlusion_packet(rays, active, test,
                              [this](auto&&... a) { return occluded_packet(a...); });
}

bool WideBvh::intersect(PreparedRay& r, TriangleHit& hit, TriangleTest test) const {
  if (test == TriangleTest::watertight) return traverse<TriangleTest::watertight, false>(r, &hit);
  return traverse<TriangleTest::moller_trumbore, false>(r, &hit);
}

bool WideBvh::occluded(const PreparedRay& r, TriangleTest test) const {
  PreparedRay copy = r;
  if (test == TriangleTest::watertight)
    return traverse<TriangleTest::watertight, true>(copy, nullptr);
  return traverse<TriangleTest::moller_trumbore, true>(copy, nullptr);
}

} // namespace specula::accel
