#include "specula/accel/bvh/bvh.h"

#include "specula/accel/common/simd_lanes.h"
#include "specula/core/assert.h"

#include <tbb/parallel_invoke.h>

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <limits>
#include <type_traits>

namespace specula::accel {

namespace {

using gpu::BvhNode;
using gpu::kBvhUnbuilt;

constexpr std::uint32_t kMaxBins = 64;
/// Subtrees over at least this many primitives are built as parallel tasks (eager builds only).
constexpr std::uint32_t kParallelMin = 4096;
constexpr std::uint32_t kNoLazy = std::numeric_limits<std::uint32_t>::max();
constexpr float kInf = std::numeric_limits<float>::infinity();

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

/// Half the surface area; 0 for an empty box (so empty bins and NaN primitives cost nothing).
float half_area(const vec3& lo, const vec3& hi) {
  const vec3 d = hi - lo;
  if (!(d.x >= 0.0f && d.y >= 0.0f && d.z >= 0.0f)) return 0.0f;
  return d.x * d.y + d.y * d.z + d.z * d.x;
}

/// x - x is 0 exactly when x is finite (no -ffinite-math-only here): one test for nine floats.
bool all_finite(const vec3& a, const vec3& b, const vec3& c) {
  const vec3 d = (a - a) + (b - b) + (c - c);
  return d.x == 0.0f && d.y == 0.0f && d.z == 0.0f;
}

/// A primitive's box as the tree sees it: non-finite boxes become empty (never entered).
Aabb sanitize(const Aabb& b) {
  if (!all_finite(b.min, b.max, b.min) || b.empty()) return Aabb{};
  return b;
}

Aabb triangle_box(const TriangleView& tris, std::uint32_t prim) {
  const uvec3 tri = tris.triangles[prim];
  const vec3& a = tris.positions[tri.x];
  const vec3& b = tris.positions[tri.y];
  const vec3& c = tris.positions[tri.z];
  if (!all_finite(a, b, c)) return Aabb{};
  return {glm::min(a, glm::min(b, c)), glm::max(a, glm::max(b, c))};
}

/// A primitive during a build: its box and its index, permuted in place by the partitions.
struct Ref {
  vec3 lo;
  std::uint32_t prim;
  vec3 hi;
  std::uint32_t pad;
  [[nodiscard]] vec3 centroid() const { return 0.5f * (lo + hi); } // NaN for an empty box
};

/// Bin of centroid coordinate c; NaN (an empty box) goes to bin 0, never out of range.
std::uint32_t bin_of(float c, float lo, float scale, std::uint32_t bins) {
  const float f = (c - lo) * scale;
  if (!(f > 0.0f)) return 0;
  return f < float(bins - 1) ? std::uint32_t(f) : bins - 1;
}

/// A subtree being built: nodes[0] is its root, child indices are local.
struct LocalTree {
  std::vector<BvhNode> nodes;
  std::vector<std::uint8_t> depth;
  void reset() {
    nodes.assign(1, BvhNode{});
    depth.assign(1, 0);
  }
};

/// Unnormalised SAH cost of each subtree (area · cost), children after parents in `nodes`.
void subtree_sah(std::span<const BvhNode> nodes, float ct, float ci, std::vector<float>& s) {
  s.resize(nodes.size());
  for (std::size_t i = nodes.size(); i-- > 0;) {
    const BvhNode& n = nodes[i];
    const float area = half_area(n.bounds_min, n.bounds_max);
    if (n.count == 0)
      s[i] = ct * area + s[n.index] + s[n.index + 1];
    else // a leaf, or an unbuilt node costed as one
      s[i] = ci * float(n.count & ~kBvhUnbuilt) * area;
  }
}

float normalised(float s, const BvhNode& n) {
  const float area = half_area(n.bounds_min, n.bounds_max);
  return area > 0.0f ? s / area : 0.0f;
}

/// Binned SAH builder (Wald 2007) over a range of Refs whose entries start at first_entry.
class Builder {
public:
  Builder(const BvhBuildOptions& options, std::uint32_t first_entry, std::uint32_t stop_depth,
          bool parallel)
      : opt_(options), first_entry_(first_entry), stop_depth_(stop_depth), parallel_(parallel) {}

  void build(std::span<Ref> refs, const Aabb& bounds, std::uint32_t depth, LocalTree& out) const {
    out.reset();
    node(refs.data(), 0, std::uint32_t(refs.size()), bounds, depth, out, 0);
  }

private:
  struct Split {
    bool leaf = true;
    std::uint32_t mid = 0;
    Aabb left, right;
  };
  struct Bin { // no default initialisation: only the bins in use are cleared, per node
    vec3 lo, hi;
    std::uint32_t count;
  };

  void node(Ref* refs, std::uint32_t begin, std::uint32_t end, const Aabb& bounds,
            std::uint32_t depth, LocalTree& out, std::uint32_t slot) const {
    const std::uint32_t n = end - begin;
    BvhNode node{bounds.min, first_entry_ + begin, bounds.max, n};
    out.depth[slot] = std::uint8_t(std::min<std::uint32_t>(depth, 255));
    if (depth >= stop_depth_ && n > opt_.max_leaf) {
      node.count = kBvhUnbuilt | n;
      out.nodes[slot] = node;
      return;
    }
    const Split s = split(refs, begin, end, bounds, depth);
    if (s.leaf) {
      out.nodes[slot] = node;
      return;
    }
    const auto pair = std::uint32_t(out.nodes.size());
    out.nodes.resize(pair + 2);
    out.depth.resize(pair + 2);
    node.index = pair;
    node.count = 0;
    out.nodes[slot] = node;
    if (parallel_ && n >= kParallelMin) {
      // Both halves as tasks into their own arrays, appended in the order the sequential build
      // writes them: the same tree whatever the thread count.
      LocalTree l, r;
      tbb::parallel_invoke(
          [&] {
            l.reset();
            this->node(refs, begin, s.mid, s.left, depth + 1, l, 0);
          },
          [&] {
            r.reset();
            this->node(refs, s.mid, end, s.right, depth + 1, r, 0);
          });
      append(out, pair, l);
      append(out, pair + 1, r);
    } else {
      this->node(refs, begin, s.mid, s.left, depth + 1, out, pair);
      this->node(refs, s.mid, end, s.right, depth + 1, out, pair + 1);
    }
  }

  static void append(LocalTree& out, std::uint32_t slot, const LocalTree& sub) {
    const auto base = std::uint32_t(out.nodes.size());
    auto remap = [base](BvhNode n) {
      if (n.count == 0) n.index = n.index - 1 + base;
      return n;
    };
    out.nodes[slot] = remap(sub.nodes[0]);
    out.depth[slot] = sub.depth[0];
    for (std::size_t i = 1; i < sub.nodes.size(); ++i) {
      out.nodes.push_back(remap(sub.nodes[i]));
      out.depth.push_back(sub.depth[i]);
    }
  }

  // Not inlined: keeps the bins off the recursion's frames.
  [[gnu::noinline]] Split split(Ref* refs, std::uint32_t begin, std::uint32_t end,
                                const Aabb& bounds, std::uint32_t depth) const {
    Split s;
    const std::uint32_t n = end - begin;
    if (n <= 1) return s;
    vec3 cmin(kInf), cmax(-kInf);
    for (std::uint32_t i = begin; i < end; ++i) {
      const vec3 c = refs[i].centroid();
      for (int a = 0; a < 3; ++a) { // NaN centroids (empty boxes) are skipped
        cmin[a] = c[a] < cmin[a] ? c[a] : cmin[a];
        cmax[a] = c[a] > cmax[a] ? c[a] : cmax[a];
      }
    }
    const float area = half_area(bounds.min, bounds.max);
    const float leaf_cost = opt_.intersection_cost * float(n) * area;

    if (depth < Bvh::kSahDepthLimit) {
      const std::uint32_t bins = opt_.bins;
      Bin bin[3][kMaxBins];
      for (auto& axis_bins : bin)
        for (std::uint32_t i = 0; i < bins; ++i) axis_bins[i] = {vec3(kInf), vec3(-kInf), 0};
      float scale[3];
      bool usable[3];
      for (int a = 0; a < 3; ++a) {
        const float extent = cmax[a] - cmin[a];
        usable[a] = extent > 0.0f && extent < kInf;
        scale[a] = usable[a] ? float(bins) / extent : 0.0f;
      }
      for (std::uint32_t i = begin; i < end; ++i) {
        const Ref& r = refs[i];
        const vec3 c = r.centroid();
        for (int a = 0; a < 3; ++a) {
          if (!usable[a]) continue;
          Bin& b = bin[a][bin_of(c[a], cmin[a], scale[a], bins)];
          b.lo = glm::min(b.lo, r.lo);
          b.hi = glm::max(b.hi, r.hi);
          ++b.count;
        }
      }
      float best = kInf;
      int best_axis = -1;
      std::uint32_t best_bin = 0;
      std::array<float, kMaxBins> right_cost{};
      for (int a = 0; a < 3; ++a) {
        if (!usable[a]) continue;
        Aabb box;
        std::uint32_t count = 0;
        for (std::uint32_t i = bins - 1; i > 0; --i) {
          box.grow(Aabb{bin[a][i].lo, bin[a][i].hi});
          count += bin[a][i].count;
          right_cost[i] = count ? half_area(box.min, box.max) * float(count) : -1.0f;
        }
        box = Aabb{};
        count = 0;
        for (std::uint32_t i = 1; i < bins; ++i) {
          box.grow(Aabb{bin[a][i - 1].lo, bin[a][i - 1].hi});
          count += bin[a][i - 1].count;
          if (count == 0 || right_cost[i] < 0.0f) continue;
          const float cost = opt_.traversal_cost * area +
                             opt_.intersection_cost *
                                 (half_area(box.min, box.max) * float(count) + right_cost[i]);
          if (cost < best) {
            best = cost;
            best_axis = a;
            best_bin = i;
          }
        }
      }
      if (best_axis >= 0) {
        if (n <= opt_.max_leaf && leaf_cost <= best) return s;
        const int a = best_axis;
        Ref* mid = std::partition(refs + begin, refs + end, [&](const Ref& r) {
          return bin_of(r.centroid()[a], cmin[a], scale[a], bins) < best_bin;
        });
        s.leaf = false;
        s.mid = std::uint32_t(mid - refs);
        for (std::uint32_t i = 0; i < bins; ++i)
          (i < best_bin ? s.left : s.right).grow(Aabb{bin[a][i].lo, bin[a][i].hi});
        return s;
      }
    }
    if (n <= opt_.max_leaf) return s;
    // Median split on the widest centroid axis: when the centroids coincide (nothing to bin) or
    // below kSahDepthLimit (bounds the depth).
    int axis = 0;
    float widest = -1.0f;
    for (int a = 0; a < 3; ++a) {
      const float extent = cmax[a] - cmin[a];
      if (extent > widest) {
        widest = extent;
        axis = a;
      }
    }
    auto key = [axis](const Ref& r) {
      const float c = r.centroid()[axis];
      return c == c ? c : -kInf;
    };
    s.leaf = false;
    s.mid = begin + n / 2;
    std::nth_element(refs + begin, refs + s.mid, refs + end,
                     [&](const Ref& x, const Ref& y) { return key(x) < key(y); });
    for (std::uint32_t i = begin; i < end; ++i) {
      Aabb& b = i < s.mid ? s.left : s.right;
      b.min = glm::min(b.min, refs[i].lo);
      b.max = glm::max(b.max, refs[i].hi);
    }
    return s;
  }

  const BvhBuildOptions& opt_;
  std::uint32_t first_entry_;
  std::uint32_t stop_depth_;
  bool parallel_;
};

BvhBuildOptions sanitized(BvhBuildOptions o) {
  o.bins = std::clamp<std::uint32_t>(o.bins, 2, kMaxBins);
  o.max_leaf = std::max<std::uint32_t>(o.max_leaf, 1);
  o.lazy_depth = std::clamp<std::uint32_t>(o.lazy_depth, 1, 200);
  return o;
}

Aabb refs_bounds(std::span<const Ref> refs) {
  Aabb b;
  for (const Ref& r : refs) {
    b.min = glm::min(b.min, r.lo);
    b.max = glm::max(b.max, r.hi);
  }
  return b;
}

// ---- Packets ------------------------------------------------------------------------------------

template <int N>
struct PacketData {
  alignas(32) float org[3][N];
  alignas(32) float inv[3][N];
  alignas(32) std::uint32_t neg[3][N]; ///< all ones where the direction is negative
  alignas(32) float tnear[N];
  alignas(32) float tfar[N];
};

struct ChildHits {
  std::uint32_t mask[2];
  float entry[2];
};

// The two children of a node against a packet: intersect_box lane by lane (the same operations,
// max/min keep the current bound on NaN as the scalar test does).
ChildHits box2_sse(const PacketData<4>& p, const BvhNode* c, std::uint32_t mask) {
  ChildHits out;
  const __m128 scale = _mm_set1_ps(kBoxFarScale);
  for (int k = 0; k < 2; ++k) {
    __m128 t0 = _mm_load_ps(p.tnear);
    __m128 t1 = _mm_load_ps(p.tfar);
    for (int a = 0; a < 3; ++a) {
      const __m128 o = _mm_load_ps(p.org[a]);
      const __m128 inv = _mm_load_ps(p.inv[a]);
      const __m128 neg = _mm_castsi128_ps(_mm_load_si128(reinterpret_cast<const __m128i*>(p.neg[a])));
      const __m128 tl = _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(c[k].bounds_min[a]), o), inv);
      const __m128 th = _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(c[k].bounds_max[a]), o), inv);
      const __m128 tn = _mm_or_ps(_mm_and_ps(neg, th), _mm_andnot_ps(neg, tl));
      const __m128 tf = _mm_mul_ps(_mm_or_ps(_mm_and_ps(neg, tl), _mm_andnot_ps(neg, th)), scale);
      t0 = _mm_max_ps(tn, t0);
      t1 = _mm_min_ps(tf, t1);
    }
    const __m128 hit = _mm_cmple_ps(t0, t1);
    const std::uint32_t m = std::uint32_t(_mm_movemask_ps(hit)) & mask;
    // The nearest entry over the lanes that hit (+inf elsewhere).
    const __m128 live = _mm_and_ps(hit, simd_sse::vlanes(mask));
    out.mask[k] = m;
    out.entry[k] = m != 0 ? simd_sse::vhmin(simd_sse::vselect(_mm_set1_ps(kInf), t0, live)) : kInf;
  }
  return out;
}

__attribute__((target("avx2,fma"))) ChildHits box2_avx2(const PacketData<8>& p, const BvhNode* c,
                                                        std::uint32_t mask) {
  ChildHits out;
  const __m256 scale = _mm256_set1_ps(kBoxFarScale);
  for (int k = 0; k < 2; ++k) {
    __m256 t0 = _mm256_load_ps(p.tnear);
    __m256 t1 = _mm256_load_ps(p.tfar);
    for (int a = 0; a < 3; ++a) {
      const __m256 o = _mm256_load_ps(p.org[a]);
      const __m256 inv = _mm256_load_ps(p.inv[a]);
      const __m256 neg =
          _mm256_castsi256_ps(_mm256_load_si256(reinterpret_cast<const __m256i*>(p.neg[a])));
      const __m256 tl = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(c[k].bounds_min[a]), o), inv);
      const __m256 th = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(c[k].bounds_max[a]), o), inv);
      const __m256 tn = _mm256_blendv_ps(tl, th, neg);
      const __m256 tf = _mm256_mul_ps(_mm256_blendv_ps(th, tl, neg), scale);
      t0 = _mm256_max_ps(tn, t0);
      t1 = _mm256_min_ps(tf, t1);
    }
    const __m256 hit = _mm256_cmp_ps(t0, t1, _CMP_LE_OQ);
    const std::uint32_t m = std::uint32_t(_mm256_movemask_ps(hit)) & mask;
    // The nearest entry over the lanes that hit (+inf elsewhere).
    const __m256 live = _mm256_and_ps(hit, simd_avx2::vlanes(mask));
    out.mask[k] = m;
    out.entry[k] =
        m != 0 ? simd_avx2::vhmin(simd_avx2::vselect(_mm256_set1_ps(kInf), t0, live)) : kInf;
  }
  return out;
}

/// The farthest tfar over the lanes in `mask` (-inf for none).
__attribute__((target("avx2"))) float reach_avx2(const PacketData<8>& p, std::uint32_t mask) {
  return simd_avx2::vhmax(
      simd_avx2::vselect(_mm256_set1_ps(-kInf), _mm256_load_ps(p.tfar), simd_avx2::vlanes(mask)));
}

/// The vector operations of one packet width: the two children's boxes, and a leaf's triangles
/// against the lanes (simd_lanes.h; used when the lanes share their ray space).
struct BoxTestSse {
  using Lanes = simd_sse::WatertightLanes;
  ChildHits operator()(const PacketData<4>& p, const BvhNode* c, std::uint32_t mask) const {
    return box2_sse(p, c, mask);
  }
  /// The farthest tfar over the lanes in `mask` (-inf for none).
  static float reach(const PacketData<4>& p, std::uint32_t mask) {
    return simd_sse::vhmax(
        simd_sse::vselect(_mm_set1_ps(-kInf), _mm_load_ps(p.tfar), simd_sse::vlanes(mask)));
  }
  static bool make_lanes(const PreparedRay* rays, unsigned mask, Lanes& w) {
    return simd_sse::make_watertight_lanes(rays, mask, w);
  }
  static bool prepare(const RayPacket<4>& rays, const bool* active, PreparedRay* out,
                      unsigned& mask, std::uint32_t neg[3], Lanes& w) {
    return simd_sse::prepare_coherent_lanes(rays, active, nullptr, out, nullptr, nullptr, mask, neg,
                                            w);
  }
  static void store(float* p, const __m128& v) { _mm_store_ps(p, v); }
  static void leaf(const Lanes& w, PreparedRay* rays, TriangleHit* hits, unsigned mask,
                   const TriangleView& tris, const std::uint32_t* ids, std::uint32_t count) {
    simd_sse::intersect_leaf_lanes(w, rays, hits, mask, tris, ids, count);
  }
};
struct BoxTestAvx2 {
  using Lanes = simd_avx2::WatertightLanes;
  ChildHits operator()(const PacketData<8>& p, const BvhNode* c, std::uint32_t mask) const {
    return box2_avx2(p, c, mask);
  }
  static float reach(const PacketData<8>& p, std::uint32_t mask) { return reach_avx2(p, mask); }
  static bool make_lanes(const PreparedRay* rays, unsigned mask, Lanes& w) {
    return simd_avx2::make_watertight_lanes(rays, mask, w);
  }
  static bool prepare(const RayPacket<8>& rays, const bool* active, PreparedRay* out,
                      unsigned& mask, std::uint32_t neg[3], Lanes& w) {
    return simd_avx2::prepare_coherent_lanes(rays, active, nullptr, out, nullptr, nullptr, mask,
                                             neg, w);
  }
  /// Copies a vector of the lanes into an array (bytewise: this caller is not compiled for AVX).
  static void store(float* p, const __m256& v) { std::memcpy(p, &v, sizeof(v)); }
  static void leaf(const Lanes& w, PreparedRay* rays, TriangleHit* hits, unsigned mask,
                   const TriangleView& tris, const std::uint32_t* ids, std::uint32_t count) {
    simd_avx2::intersect_leaf_lanes(w, rays, hits, mask, tris, ids, count);
  }
};

} // namespace

// ---- Construction -------------------------------------------------------------------------------

Bvh::Bvh() : mutex_(std::make_unique<std::mutex>()) {}
Bvh::Bvh(Bvh&&) noexcept = default;
Bvh& Bvh::operator=(Bvh&&) noexcept = default;
Bvh::~Bvh() = default;

void Bvh::build(const TriangleView& tris, const BvhBuildOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<Aabb> boxes(tris.count);
  for (std::uint32_t i = 0; i < tris.count; ++i) boxes[i] = triangle_box(tris, i);
  build_common(boxes, options);
  tris_ = tris;
  over_triangles_ = true;
  lazy_boxes_.clear();
  stats_.build_ms = ms_since(start);
}

void Bvh::build(std::span<const Aabb> boxes, const BvhBuildOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  build_common(boxes, options);
  tris_ = {};
  over_triangles_ = false;
  if (options_.lazy) lazy_boxes_.assign(boxes.begin(), boxes.end());
  else lazy_boxes_.clear();
  stats_.build_ms = ms_since(start);
}

void Bvh::build_common(std::span<const Aabb> prim_boxes, const BvhBuildOptions& options) {
  if (!mutex_) mutex_ = std::make_unique<std::mutex>();
  options_ = sanitized(options);
  prim_count_ = std::uint32_t(prim_boxes.size());
  nodes_.clear();
  indices_.clear();
  built_cost_.clear();
  lazy_depth_.clear();
  used_ = 0;
  holes_ = 0;
  stats_ = {};
  if (prim_count_ == 0) return;

  std::vector<Ref> refs(prim_count_);
  for (std::uint32_t i = 0; i < prim_count_; ++i) {
    const Aabb b = sanitize(prim_boxes[i]);
    refs[i] = {b.min, i, b.max, 0};
  }
  const Builder builder(options_, 0, options_.lazy ? options_.lazy_depth : kNoLazy, true);
  LocalTree tree;
  builder.build(refs, refs_bounds(refs), 0, tree);

  indices_.resize(prim_count_);
  for (std::uint32_t i = 0; i < prim_count_; ++i) indices_[i] = refs[i].prim;
  nodes_ = std::move(tree.nodes);
  used_ = nodes_.size();
  std::vector<float> s;
  subtree_sah(nodes_, options_.traversal_cost, options_.intersection_cost, s);
  built_cost_.resize(used_);
  for (std::size_t i = 0; i < used_; ++i) built_cost_[i] = normalised(s[i], nodes_[i]);
  if (options_.lazy) {
    // Worst case 2n - 1 nodes: expansions append without ever moving the array under readers.
    const std::size_t capacity = std::max<std::size_t>(used_, 2 * std::size_t(prim_count_) - 1);
    nodes_.resize(capacity);
    built_cost_.resize(capacity);
    lazy_depth_ = std::move(tree.depth);
    lazy_depth_.resize(capacity);
  }
  update_stats();
}

void Bvh::update_stats() {
  const double build_ms = stats_.build_ms;
  const std::uint32_t expansions = stats_.lazy_expansions;
  stats_ = {};
  stats_.build_ms = build_ms;
  stats_.lazy_expansions = expansions;
  stats_.bytes = nodes_.size() * sizeof(BvhNode) + indices_.size() * sizeof(std::uint32_t) +
                 built_cost_.size() * sizeof(float) + lazy_depth_.size();
  if (used_ == 0) return;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack{{0u, 0u}};
  while (!stack.empty()) {
    const auto [node, depth] = stack.back();
    stack.pop_back();
    ++stats_.nodes;
    stats_.max_depth = std::max(stats_.max_depth, depth);
    const BvhNode& n = nodes_[node];
    if (n.count == 0) {
      stack.push_back({n.index, depth + 1});
      stack.push_back({n.index + 1, depth + 1});
    } else if (!(n.count & kBvhUnbuilt)) {
      ++stats_.leaves;
    }
  }
  stats_.sah_cost = sah_cost();
}

void Bvh::subtree_costs(std::vector<float>& s) const {
  subtree_sah({nodes_.data(), used_}, options_.traversal_cost, options_.intersection_cost, s);
}

float Bvh::sah_cost() const {
  if (used_ == 0) return 0.0f;
  std::vector<float> s;
  subtree_costs(s);
  return normalised(s[0], nodes_[0]);
}

Aabb Bvh::bounds() const {
  if (used_ == 0) return {};
  return {nodes_[0].bounds_min, nodes_[0].bounds_max};
}

// ---- Lazy expansion -----------------------------------------------------------------------------

std::uint32_t Bvh::expand(std::uint32_t node) const {
  std::lock_guard lock(*mutex_);
  std::atomic_ref<std::uint32_t> count_ref(nodes_[node].count);
  const std::uint32_t count = count_ref.load(std::memory_order_relaxed);
  if (!(count & kBvhUnbuilt)) return count; // another thread expanded it meanwhile
  const std::uint32_t first = nodes_[node].index;
  const std::uint32_t n = count & ~kBvhUnbuilt;
  std::vector<Ref> refs(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::uint32_t prim = indices_[first + i];
    const Aabb b = over_triangles_ ? triangle_box(tris_, prim) : sanitize(lazy_boxes_[prim]);
    refs[i] = {b.min, prim, b.max, 0};
  }
  const std::uint32_t depth = lazy_depth_[node];
  // Sequential: a task-stealing wait while holding the mutex could re-enter it on this thread.
  const Builder builder(options_, first, depth + options_.lazy_depth, false);
  LocalTree tree;
  builder.build(refs, refs_bounds(refs), depth, tree);

  std::vector<float> s;
  subtree_sah(tree.nodes, options_.traversal_cost, options_.intersection_cost, s);
  const auto base = std::uint32_t(used_);
  SPECULA_ASSERT(base + tree.nodes.size() - 1 <= nodes_.size());
  auto remap = [base](BvhNode b) {
    if (b.count == 0) b.index = b.index - 1 + base;
    return b;
  };
  for (std::size_t i = 1; i < tree.nodes.size(); ++i) {
    const std::size_t slot = base + i - 1;
    nodes_[slot] = remap(tree.nodes[i]);
    built_cost_[slot] = normalised(s[i], tree.nodes[i]);
    lazy_depth_[slot] = tree.depth[i];
    stats_.max_depth = std::max<std::uint32_t>(stats_.max_depth, tree.depth[i]);
    if (tree.nodes[i].count != 0 && !(tree.nodes[i].count & kBvhUnbuilt)) ++stats_.leaves;
  }
  for (std::uint32_t i = 0; i < n; ++i) indices_[first + i] = refs[i].prim;
  used_ += tree.nodes.size() - 1;
  stats_.nodes += std::uint32_t(tree.nodes.size() - 1);
  ++stats_.lazy_expansions;
  built_cost_[node] = normalised(s[0], tree.nodes[0]);
  const BvhNode root = remap(tree.nodes[0]);
  nodes_[node].index = root.index;
  // Publish: a reader that acquires the new count sees the children and the entries.
  count_ref.store(root.count, std::memory_order_release);
  return root.count;
}

void Bvh::expand_all() const {
  if (used_ == 0) return;
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t node = stack.back();
    stack.pop_back();
    std::uint32_t count = load_count(node);
    if (count & kBvhUnbuilt) count = expand(node);
    if (count == 0) {
      stack.push_back(nodes_[node].index);
      stack.push_back(nodes_[node].index + 1);
    }
  }
}

// ---- Refit --------------------------------------------------------------------------------------

void Bvh::refit(const TriangleView& tris) {
  SPECULA_ASSERT(over_triangles_ && tris.count == prim_count_);
  tris_ = tris;
  refit_nodes(&tris, {});
}

void Bvh::refit(std::span<const Aabb> boxes) {
  SPECULA_ASSERT(!over_triangles_ && boxes.size() == prim_count_);
  if (options_.lazy) lazy_boxes_.assign(boxes.begin(), boxes.end());
  refit_nodes(nullptr, boxes);
}

void Bvh::refit_nodes(const TriangleView* tris, std::span<const Aabb> boxes) {
  // Children always follow their parent in the array: one reverse sweep is bottom-up.
  BvhNode* nodes = nodes_.data();
  const std::uint32_t* entries = indices_.data();
  for (std::size_t i = used_; i-- > 0;) {
    BvhNode& n = nodes[i];
    if (n.count == 0) {
      const BvhNode& a = nodes[n.index];
      const BvhNode& b = nodes[n.index + 1];
      n.bounds_min = glm::min(a.bounds_min, b.bounds_min);
      n.bounds_max = glm::max(a.bounds_max, b.bounds_max);
      continue;
    }
    // A leaf, or an unbuilt node (its whole range): the union of its primitives' boxes.
    vec3 lo(kInf), hi(-kInf);
    const std::uint32_t end = n.index + (n.count & ~kBvhUnbuilt);
    if (tris) {
      const vec3* p = tris->positions;
      const uvec3* t = tris->triangles;
      for (std::uint32_t e = n.index; e < end; ++e) {
        const uvec3 tri = t[entries[e]];
        const vec3 a = p[tri.x], b = p[tri.y], c = p[tri.z];
        if (!all_finite(a, b, c)) continue;
        lo = glm::min(lo, glm::min(a, glm::min(b, c)));
        hi = glm::max(hi, glm::max(a, glm::max(b, c)));
      }
    } else {
      for (std::uint32_t e = n.index; e < end; ++e) {
        const Aabb b = sanitize(boxes[entries[e]]);
        lo = glm::min(lo, b.min);
        hi = glm::max(hi, b.max);
      }
    }
    n.bounds_min = lo;
    n.bounds_max = hi;
  }
}

// ---- Selective restructuring --------------------------------------------------------------------

RestructureStats Bvh::restructure(const TriangleView& tris, float threshold) {
  SPECULA_ASSERT(over_triangles_ && tris.count == prim_count_);
  tris_ = tris;
  return restructure_common(&tris, {}, threshold);
}

RestructureStats Bvh::restructure(std::span<const Aabb> boxes, float threshold) {
  SPECULA_ASSERT(!over_triangles_ && boxes.size() == prim_count_);
  if (options_.lazy) lazy_boxes_.assign(boxes.begin(), boxes.end());
  return restructure_common(nullptr, boxes, threshold);
}

RestructureStats Bvh::restructure_common(const TriangleView* tris, std::span<const Aabb> boxes,
                                         float threshold) {
  const auto start = std::chrono::steady_clock::now();
  RestructureStats out;
  if (used_ == 0) return out;
  std::vector<float> s;
  subtree_costs(s);
  out.sah_before = normalised(s[0], nodes_[0]);

  // Top down: the first degraded node on each path is rebuilt, its descendants not looked at.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack{{0u, 0u}}, selected;
  while (!stack.empty()) {
    const auto [node, depth] = stack.back();
    stack.pop_back();
    ++out.nodes_visited;
    const BvhNode& n = nodes_[node];
    if (n.count != 0) continue; // leaves cannot improve; unbuilt nodes are built fresh on visit
    const float now = normalised(s[node], n);
    const float then = built_cost_[node];
    if (then > 0.0f && now > threshold * then) {
      selected.push_back({node, depth});
    } else {
      stack.push_back({n.index, depth + 1});
      stack.push_back({n.index + 1, depth + 1});
    }
  }
  const std::size_t used_before = used_;
  for (const auto& [node, depth] : selected)
    out.primitives_rebuilt += rebuild_subtree(node, depth, tris, boxes);
  out.subtrees_rebuilt = std::uint32_t(selected.size());
  // A lazy tree must keep room for every future expansion; elsewhere holes are tolerated until
  // they are a quarter of the array.
  if ((options_.lazy && (holes_ > 0 || used_ > used_before)) || std::size_t(holes_) * 4 > used_)
    compact();
  if (!selected.empty()) update_stats();
  out.sah_after = selected.empty() ? out.sah_before : stats_.sah_cost;
  out.ms = ms_since(start);
  return out;
}

std::uint32_t Bvh::rebuild_subtree(std::uint32_t root, std::uint32_t depth,
                                   const TriangleView* tris, std::span<const Aabb> boxes) {
  // The old subtree: its sibling pairs (slots to reuse) and its entry range (contiguous).
  std::vector<std::uint32_t> pairs;
  std::uint32_t first = std::numeric_limits<std::uint32_t>::max(), total = 0;
  std::vector<std::uint32_t> stack{root};
  while (!stack.empty()) {
    const BvhNode& n = nodes_[stack.back()];
    stack.pop_back();
    if (n.count == 0) {
      pairs.push_back(n.index);
      stack.push_back(n.index);
      stack.push_back(n.index + 1);
    } else {
      first = std::min(first, n.index);
      total += n.count & ~kBvhUnbuilt;
    }
  }
  std::vector<Ref> refs(total);
  for (std::uint32_t i = 0; i < total; ++i) {
    const std::uint32_t prim = indices_[first + i];
    const Aabb b = tris ? triangle_box(*tris, prim) : sanitize(boxes[prim]);
    refs[i] = {b.min, prim, b.max, 0};
  }
  const Builder builder(options_, first, kNoLazy, true);
  LocalTree tree;
  builder.build(refs, refs_bounds(refs), depth, tree);
  for (std::uint32_t i = 0; i < total; ++i) indices_[first + i] = refs[i].prim;
  std::vector<float> s;
  subtree_sah(tree.nodes, options_.traversal_cost, options_.intersection_cost, s);

  // Slots: the root keeps its own; pairs in breadth-first order take the old pairs in ascending
  // order, then new ones at the end, so children still follow their parent.
  std::sort(pairs.begin(), pairs.end());
  std::vector<std::uint32_t> slot(tree.nodes.size());
  slot[0] = root;
  std::size_t next = 0;
  std::vector<std::uint32_t> queue{0};
  for (std::size_t q = 0; q < queue.size(); ++q) {
    const BvhNode& n = tree.nodes[queue[q]];
    if (n.count != 0) continue;
    std::uint32_t pair;
    if (next < pairs.size()) {
      pair = pairs[next++];
    } else {
      pair = std::uint32_t(used_);
      used_ += 2;
      if (nodes_.size() < used_) {
        nodes_.resize(used_);
        built_cost_.resize(used_);
        if (!lazy_depth_.empty()) lazy_depth_.resize(used_);
      }
    }
    slot[n.index] = pair;
    slot[n.index + 1] = pair + 1;
    queue.push_back(n.index);
    queue.push_back(n.index + 1);
  }
  for (std::size_t i = 0; i < tree.nodes.size(); ++i) {
    BvhNode n = tree.nodes[i];
    if (n.count == 0) n.index = slot[n.index];
    nodes_[slot[i]] = n;
    built_cost_[slot[i]] = normalised(s[i], tree.nodes[i]);
    if (!lazy_depth_.empty()) lazy_depth_[slot[i]] = tree.depth[i];
  }
  // Pairs left over are holes: unbuilt nodes over no entries, unreachable, empty boxes.
  for (; next < pairs.size(); ++next) {
    for (std::uint32_t k = 0; k < 2; ++k) {
      nodes_[pairs[next] + k] = BvhNode{vec3(kInf), 0, vec3(-kInf), kBvhUnbuilt};
      built_cost_[pairs[next] + k] = 0.0f;
    }
    holes_ += 2;
  }
  return total;
}

void Bvh::compact() {
  // Depth-first relayout, pairs in the order the build writes them.
  std::vector<BvhNode> nodes;
  std::vector<float> cost;
  std::vector<std::uint8_t> depth;
  const bool lazy = !lazy_depth_.empty();
  nodes.reserve(used_ - holes_);
  cost.reserve(used_ - holes_);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack{{0u, 0u}}; // old slot, new slot
  nodes.push_back(nodes_[0]);
  cost.push_back(built_cost_[0]);
  if (lazy) depth.push_back(lazy_depth_[0]);
  while (!stack.empty()) {
    const auto [old_slot, new_slot] = stack.back();
    stack.pop_back();
    const BvhNode& n = nodes_[old_slot];
    if (n.count != 0) continue;
    const auto pair = std::uint32_t(nodes.size());
    nodes[new_slot].index = pair;
    for (std::uint32_t k = 0; k < 2; ++k) {
      nodes.push_back(nodes_[n.index + k]);
      cost.push_back(built_cost_[n.index + k]);
      if (lazy) depth.push_back(lazy_depth_[n.index + k]);
    }
    stack.push_back({n.index + 1, pair + 1});
    stack.push_back({n.index, pair});
  }
  used_ = nodes.size();
  holes_ = 0;
  if (lazy) {
    const std::size_t capacity = std::max<std::size_t>(used_, 2 * std::size_t(prim_count_) - 1);
    nodes.resize(capacity);
    cost.resize(capacity);
    depth.resize(capacity);
  }
  nodes_ = std::move(nodes);
  built_cost_ = std::move(cost);
  lazy_depth_ = std::move(depth);
}

// ---- Traversal ----------------------------------------------------------------------------------

template <TriangleTest Test>
bool Bvh::intersect_impl(PreparedRay& r, TriangleHit& hit) const {
  bool found = false;
  traverse(r, [&](std::uint32_t prim, PreparedRay& ray) {
    found |= intersect_closest<Test>(ray, tris_, prim, hit);
    return false;
  });
  return found;
}

template <TriangleTest Test>
bool Bvh::occluded_impl(const PreparedRay& r) const {
  PreparedRay ray = r;
  bool any = false;
  traverse(ray, [&](std::uint32_t prim, PreparedRay& q) {
    any = intersect_any<Test>(q, tris_, prim);
    return any;
  });
  return any;
}

bool Bvh::intersect(PreparedRay& r, TriangleHit& hit, TriangleTest test) const {
  if (!over_triangles_) return false;
  return test == TriangleTest::watertight ? intersect_impl<TriangleTest::watertight>(r, hit)
                                          : intersect_impl<TriangleTest::moller_trumbore>(r, hit);
}

bool Bvh::occluded(const PreparedRay& r, TriangleTest test) const {
  if (!over_triangles_) return false;
  return test == TriangleTest::watertight ? occluded_impl<TriangleTest::watertight>(r)
                                          : occluded_impl<TriangleTest::moller_trumbore>(r);
}

template <int N, TriangleTest Test>
void Bvh::intersect_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active,
                           TestTag<Test>) const {
  using BoxTest = std::conditional_t<N == 8, BoxTestAvx2, BoxTestSse>;
  const BoxTest box_test{};
  if (nodes_.empty() || !over_triangles_) return;
  PacketData<N> p;
  PreparedRay lane[N];
  TriangleHit lane_hit[N];
  std::uint32_t mask = 0;
  typename BoxTest::Lanes lanes;
  // Lanes that agree on their signs and ray space are prepared in vector steps (the same bits).
  std::uint32_t neg[3];
  const bool vector_prepared = BoxTest::prepare(rays, active, lane, mask, neg, lanes);
  if (vector_prepared) {
    for (int a = 0; a < 3; ++a) {
      BoxTest::store(p.org[a], lanes.org[a]);
      BoxTest::store(p.inv[a], lanes.inv[a]);
      std::fill_n(p.neg[a], N, neg[a] != 0 ? ~0u : 0u);
    }
    std::copy_n(rays.tnear, N, p.tnear);
    std::copy_n(rays.tfar, N, p.tfar);
  } else {
    for (int i = 0; i < N; ++i) {
      lane[i] =
          PreparedRay::make(vec3(rays.ox[i], rays.oy[i], rays.oz[i]),
                            vec3(rays.dx[i], rays.dy[i], rays.dz[i]), rays.tnear[i], rays.tfar[i]);
      if (active[i] && lane[i].valid()) mask |= 1u << i;
      for (int a = 0; a < 3; ++a) {
        p.org[a][i] = lane[i].org[a];
        p.inv[a][i] = lane[i].inv_dir[a];
        p.neg[a][i] = lane[i].neg[a] ? ~0u : 0u;
      }
      p.tnear[i] = lane[i].tnear;
      p.tfar[i] = lane[i].tfar;
    }
  }
  if (mask == 0) return;
  // Leaves test a triangle against all lanes at once when the lanes share their ray space.
  const bool simd_leaves = Test == TriangleTest::watertight &&
                           (vector_prepared || BoxTest::make_lanes(lane, mask, lanes));

  struct Entry {
    std::uint32_t node, mask;
    float t_enter;
  };
  Entry stack[kStackSize];
  int top = 0;
  stack[top++] = {0, mask, -kInf};
  while (top > 0) {
    const Entry e = stack[--top];
    // The farthest any of its lanes can still go.
    if (e.t_enter > BoxTest::reach(p, e.mask)) continue;
    std::uint32_t node = e.node, m = e.mask;
    for (;;) {
      std::uint32_t count = load_count(node);
      if (count & kBvhUnbuilt) count = expand(node);
      const std::uint32_t index = nodes_[node].index;
      if (count == 0) {
        const ChildHits h = box_test(p, &nodes_[index], m);
        if (h.mask[0] && h.mask[1]) {
          const int near = h.entry[1] < h.entry[0] ? 1 : 0;
          stack[top++] = {index + std::uint32_t(1 - near), h.mask[1 - near], h.entry[1 - near]};
          node = index + std::uint32_t(near);
          m = h.mask[near];
          continue;
        }
        if (h.mask[0] || h.mask[1]) {
          const int k = h.mask[0] ? 0 : 1;
          node = index + std::uint32_t(k);
          m = h.mask[k];
          continue;
        }
        break;
      }
      if (simd_leaves) {
        BoxTest::leaf(lanes, lane, lane_hit, m, tris_, &indices_[index], count);
        for (; m; m &= m - 1) p.tfar[__builtin_ctz(m)] = lane[__builtin_ctz(m)].tfar;
        break;
      }
      // Otherwise scalar triangle tests lane by lane.
      for (; m; m &= m - 1) {
        const int i = __builtin_ctz(m);
        intersect_leaf<Test>(lane[i], tris_, &indices_[index], count, lane_hit[i]);
        p.tfar[i] = lane[i].tfar;
      }
      break;
    }
  }
  for (int i = 0; i < N; ++i) {
    if (!lane_hit[i].hit()) continue;
    rays.tfar[i] = lane[i].tfar;
    hits.set(i, lane_hit[i]);
  }
}

void Bvh::intersect4(RayPacket<4>& rays, PacketHits<4>& hits, const bool active[4],
                     TriangleTest test) const {
  run_packet(rays, hits, active, test, [this](auto&&... a) { intersect_packet(a...); });
}

void Bvh::intersect8(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                     TriangleTest test) const {
  run_packet(rays, hits, active, test, [this](auto&&... a) { intersect_packet(a...); });
}

} // namespace specula::accel
