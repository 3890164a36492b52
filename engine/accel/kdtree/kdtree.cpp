#include "specula/accel/kdtree/kdtree.h"

#include "specula/accel/common/simd_lanes.h"
#include "specula/core/assert.h"

#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <type_traits>
#include <utility>

namespace specula::accel {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr int kStackSize = 64;
constexpr std::uint32_t kMaxDepthLimit = kStackSize - 1;
/// Local triangle indices and leaf counts live in 30 bits (events pack the type above them, nodes
/// the axis below them).
constexpr std::uint32_t kMaxTriangles = 1u << 30;

// Relative slack of the traversal's interval decisions. The split distance (s - o)·(1/d) is within
// ~3 ulp of the exact one and hit distances are within a few ulp too: a child is skipped, or the
// traversal stopped after a leaf, only when the decision holds with this margin.
constexpr float kSlack = 1e-5f;
constexpr float kDown = 1.0f - kSlack;
constexpr float kUp = 1.0f + kSlack;

// Parallel build: a node with at least this many triangles builds its children as two tasks, and
// one with at least kParallelAxes sweeps and splits its three axes as three tasks. Structural
// thresholds (sizes, never thread counts), so the tree does not depend on the pool.
constexpr std::size_t kParallelChildren = 2048;
constexpr std::size_t kParallelAxes = 16384;
// A node with at least this many triangles puts its children's lists on the heap, a smaller one
// in its task's arena (see Builder::build).
constexpr std::size_t kHeapLists = 1024;

// ---- Build --------------------------------------------------------------------------------------

// Event types in sweep order at equal positions (Wald & Havran §5.1: end < planar < start).
enum : std::uint32_t { kEnd = 0, kPlanar = 1, kStart = 2 };

/// A position as an unsigned key in the same order (IEEE bits with the sign folded in; -0 is made
/// +0 first, so equal positions have equal keys).
[[nodiscard]] inline std::uint32_t ordered_key(float pos) {
  const auto u = std::bit_cast<std::uint32_t>(pos + 0.0f);
  return u ^ ((u >> 31) != 0 ? 0xFFFFFFFFu : 0x80000000u);
}
[[nodiscard]] inline float from_ordered_key(std::uint32_t k) {
  return std::bit_cast<float>(k ^ ((k >> 31) != 0 ? 0x80000000u : 0xFFFFFFFFu));
}

/// One event: a triangle's clipped extent starts, ends or lies flat at a position on the list's
/// axis. One 64-bit word: the position's ordered key, then the type, then the node-local triangle
/// index, so a plain integer comparison sorts by position, then type, then triangle (a total
/// order: any sort gives the same list).
struct Event {
  std::uint64_t bits;
  [[nodiscard]] std::uint32_t pos_key() const { return std::uint32_t(bits >> 32); }
  [[nodiscard]] float pos() const { return from_ordered_key(pos_key()); }
  [[nodiscard]] std::uint32_t type() const { return std::uint32_t(bits >> 30) & 3u; }
  [[nodiscard]] std::uint32_t local() const { return std::uint32_t(bits) & (kMaxTriangles - 1); }
};
static_assert(sizeof(Event) == 8);

[[nodiscard]] inline bool operator<(const Event& a, const Event& b) { return a.bits < b.bits; }

[[nodiscard]] inline Event make_event(float pos, std::uint32_t type, std::uint32_t local) {
  return Event{(std::uint64_t(ordered_key(pos)) << 32) | (type << 30) | local};
}

/// Per-task memory for the nodes' lists, handed out and taken back in stack order: a node marks
/// the arena, allocates its children's lists, builds both children and releases to its mark.
/// (Six heap lists per node were about a tenth of the build of a 59k-triangle mesh.)
/// Chunks are kept for reuse; one is never moved, so a list stays put while later ones are made
/// (a parallel task reads the list above the split while the task below allocates past it).
class Arena {
public:
  struct Mark {
    std::size_t chunk, used;
  };

  template <class T>
  [[nodiscard]] T* allocate(std::size_t count) {
    static_assert(alignof(T) <= kAlign);
    const std::size_t bytes = (count * sizeof(T) + kAlign - 1) & ~(kAlign - 1);
    if (chunks_.empty() || used_ + bytes > chunks_[current_].size) {
      // The next chunk, if it exists and is big enough; a chunk after the current one holds
      // nothing live, so a small one is replaced.
      std::size_t next = chunks_.empty() ? 0 : current_ + 1;
      if (next == chunks_.size() || chunks_[next].size < bytes) {
        const std::size_t last = chunks_.empty() ? 0 : chunks_.back().size;
        Chunk c;
        c.size = std::max({bytes, 2 * last, kFirstChunk});
        c.data = std::make_unique_for_overwrite<std::byte[]>(c.size);
        if (next == chunks_.size())
          chunks_.push_back(std::move(c));
        else
          chunks_[next] = std::move(c);
      }
      current_ = next;
      used_ = 0;
    }
    T* p = reinterpret_cast<T*>(chunks_[current_].data.get() + used_);
    used_ += bytes;
    return p;
  }
  [[nodiscard]] Mark mark() const { return {current_, used_}; }
  void release(Mark m) {
    current_ = m.chunk;
    used_ = m.used;
  }

private:
  static constexpr std::size_t kAlign = 16;
  static constexpr std::size_t kFirstChunk = std::size_t(1) << 20;
  struct Chunk {
    std::unique_ptr<std::byte[]> data; // from new[]: aligned for any fundamental type
    std::size_t size = 0;
  };
  std::vector<Chunk> chunks_;
  std::size_t current_ = 0, used_ = 0;
};

/// A list of a node: a fixed buffer, sized once and never value-initialised (the split writes
/// each child's list straight into it, then trims the size), in an arena or, without one, on the
/// heap (owned, freed with the list).
template <class T>
class ArenaList {
public:
  void allocate(Arena* arena, std::size_t capacity) {
    if (arena != nullptr) {
      owned_.reset();
      data_ = arena->allocate<T>(capacity);
    } else {
      owned_ = std::make_unique_for_overwrite<T[]>(capacity);
      data_ = owned_.get();
    }
    size_ = 0;
  }
  void set_size(std::size_t n) { size_ = n; }
  void push_back(const T& e) { data_[size_++] = e; }
  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] T* data() { return data_; }
  [[nodiscard]] const T* data() const { return data_; }
  [[nodiscard]] T* begin() { return data_; }
  [[nodiscard]] T* end() { return data_ + size_; }
  [[nodiscard]] const T* begin() const { return data_; }
  [[nodiscard]] const T* end() const { return data_ + size_; }
  [[nodiscard]] T& operator[](std::size_t i) { return data_[i]; }
  [[nodiscard]] const T& operator[](std::size_t i) const { return data_[i]; }

private:
  std::unique_ptr<T[]> owned_;
  T* data_ = nullptr;
  std::size_t size_ = 0;
};

using EventList = ArenaList<Event>;
using EventLists = std::array<EventList, 3>;
/// The straddling triangles' new events of one child and axis: a buffer that only grows (sized
/// before the node's straddlers are clipped, so a push does not check its room).
class NewEvents {
public:
  void prepare(std::size_t capacity) {
    if (buffer_.size() < capacity) buffer_.resize(capacity);
    size_ = 0;
  }
  void push_back(const Event& e) { buffer_[size_++] = e; }
  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] Event* begin() { return buffer_.data(); }
  [[nodiscard]] Event* end() { return buffer_.data() + size_; }
  [[nodiscard]] const Event& operator[](std::size_t i) const { return buffer_[i]; }

private:
  std::vector<Event> buffer_;
  std::size_t size_ = 0;
};
using NewEventLists = std::array<NewEvents, 3>;

/// Per-task scratch arrays of split_node, reused from node to node (their capacity stays), and
/// the task's arena. A parallel child gets its own.
struct Scratch {
  std::vector<std::uint8_t> side;
  std::vector<std::uint32_t> remap, straddling, above_index;
  NewEventLists new_below, new_above;
  Arena arena;
};

/// A node waiting to be built: its box, its triangles (indices into the view, ascending) and its
/// three event lists over node-local indices into `tris`, all in an arena.
struct NodeInput {
  Aabb box;
  ArenaList<std::uint32_t> tris;
  EventLists events;
};

struct Counters {
  std::uint32_t leaves = 0, empty_leaves = 0, max_depth = 0;
  std::uint64_t references = 0, events = 0, sort_work = 0;
  double sah = 0.0; ///< Σ cost·area, divided by the root's area at the end

  void add(const Counters& o) {
    leaves += o.leaves;
    empty_leaves += o.empty_leaves;
    max_depth = std::max(max_depth, o.max_depth);
    references += o.references;
    events += o.events;
    sort_work += o.sort_work;
    sah += o.sah;
  }
};

/// A built subtree: nodes with `above` indices relative to its first node and leaf offsets
/// relative to its first index.
struct Subtree {
  std::vector<gpu::KdNode> nodes;
  std::vector<std::uint32_t> indices;
  Counters counters;
};

[[nodiscard]] float half_area(const vec3& e) { return e.x * e.y + e.y * e.z + e.z * e.x; }

[[nodiscard]] std::uint64_t sort_cost(std::size_t k) {
  return k < 2 ? 0 : std::uint64_t(k) * std::uint64_t(std::bit_width(k - 1));
}

/// Room for a clipped triangle. Sutherland–Hodgman adds at most one vertex per plane to a convex
/// polygon, and a straddler is clipped by its node's six planes and split by one more: 10. Rounded
/// vertices can make the polygon a little non-convex, so there is slack, and a step that would
/// still overflow gives up (clip_polygon returns -1; the caller then uses the boxes alone).
constexpr int kMaxPolygon = 16;

/// One Sutherland–Hodgman step: the part of polygon in[0, n) on one side of the plane at `plane`
/// on `axis` (keep_below: q[axis] <= plane, else q[axis] >= plane) into `out` (kMaxPolygon
/// vertices); returns its size, or -1 when it would not fit. Each edge (a, b) in turn, b the next
/// vertex: the crossing of the plane, if any, then b when it is inside (the output starts one
/// vertex later than the input; the polygon is the same).
int clip_polygon(const vec3* in, int n, int axis, float plane, bool keep_below, vec3* out) {
  auto inside = [&](const vec3& q) { return keep_below ? q[axis] <= plane : q[axis] >= plane; };
  int m = 0;
  const vec3* a = &in[n - 1];
  bool a_in = inside(*a);
  for (int i = 0; i < n; ++i) {
    if (m + 2 > kMaxPolygon) return -1;
    const vec3& b = in[i];
    const bool b_in = inside(b);
    if (a_in != b_in) { // a and b lie on opposite sides: the denominator is not zero
      const float t = (plane - (*a)[axis]) / (b[axis] - (*a)[axis]);
      vec3 p = *a + t * (b - *a);
      p[axis] = plane;
      out[m++] = p;
    }
    if (b_in) out[m++] = b;
    a = &b;
    a_in = b_in;
  }
  return m;
}

/// Triangle (p0, p1, p2), whose box is `whole`, clipped to `box` into `poly` (kMaxPolygon
/// vertices); returns the vertex count (0: nothing is left; -1: clipping gave up). A plane that
/// every vertex of the triangle lies inside leaves the polygon as it is.
int clip_to_box(const vec3& p0, const vec3& p1, const vec3& p2, const Aabb& whole, const Aabb& box,
                vec3* poly) {
  std::array<vec3, kMaxPolygon> other;
  vec3* in = poly;
  vec3* cut = other.data();
  in[0] = p0;
  in[1] = p1;
  in[2] = p2;
  int n = 3;
  for (int axis = 0; axis < 3 && n > 0; ++axis) {
    if (whole.min[axis] < box.min[axis]) {
      n = clip_polygon(in, n, axis, box.min[axis], false, cut);
      std::swap(in, cut);
    }
    if (n > 0 && whole.max[axis] > box.max[axis]) {
      n = clip_polygon(in, n, axis, box.max[axis], true, cut);
      std::swap(in, cut);
    }
  }
  if (n > 0 && in != poly) std::copy(in, in + n, poly);
  return n;
}

/// The bounds of polygon[0, n), a part of a triangle whose box is `whole` clipped to `box`,
/// widened by a few ulp on the triangle's non-flat axes (the clipped vertices are rounded) and
/// cut back to the box and to the triangle's own box. False when nothing is left (or n is -1).
bool polygon_bounds(const vec3* poly, int n, const Aabb& whole, const Aabb& box, Aabb& out) {
  if (n <= 0) return false;
  Aabb b;
  for (int i = 0; i < n; ++i) b.grow(poly[i]);
  for (int axis = 0; axis < 3; ++axis) {
    // Every axis the triangle has extent on, flat or not after rounding: a sliver thinner than an
    // ulp (a triangle's corner clipped by a plane a fraction of an ulp from its vertex, far from
    // the origin) rounds to a flat box in the cell's face, and would then go to a flat cell of its
    // own, leaving the cell it cuts through without it. Only a triangle lying in an axis plane is
    // flat there exactly.
    if (whole.max[axis] > whole.min[axis]) {
      const float pad = 4.0f * std::numeric_limits<float>::epsilon() *
                        std::max(std::abs(b.min[axis]), std::abs(b.max[axis]));
      b.min[axis] -= pad;
      b.max[axis] += pad;
    }
  }
  // Cut back to the triangle's own box too: the padding must not reach past the triangle (its
  // box is exact), or a later plane between the two could find the triangle on both sides of it
  // and its box in a child inverted.
  b.min = glm::max(b.min, glm::max(box.min, whole.min));
  b.max = glm::min(b.max, glm::min(box.max, whole.max));
  if (b.empty()) return false;
  out = b;
  return true;
}

/// Sorts the root's event list, made triangle by triangle (equal positions and types are already
/// in ascending index order): a stable least-significant-digit radix sort on the 34 bits above
/// the index, in three passes of 11, 11 and 12 bits, through `tmp` (room for n). The result is the
/// list sorted as whole words, as std::sort would leave it, in linear time. A pass whose digit is
/// the same in every event is skipped. Returns the events moved (the work counter's measure).
std::uint64_t radix_sort_root_events(Event* data, std::size_t n, Event* tmp) {
  constexpr int kShift[3] = {30, 41, 52};
  constexpr int kBits[3] = {11, 11, 12};
  std::vector<std::uint32_t> count((std::size_t(1) << 11) * 2 + (std::size_t(1) << 12), 0);
  std::uint32_t* hist[3] = {count.data(), count.data() + (1u << 11), count.data() + (2u << 11)};
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint64_t b = data[i].bits;
    for (int p = 0; p < 3; ++p) ++hist[p][(b >> kShift[p]) & ((1u << kBits[p]) - 1u)];
  }
  std::uint64_t moved = n;
  Event* from = data;
  Event* to = tmp;
  for (int p = 0; p < 3; ++p) {
    const std::size_t buckets = std::size_t(1) << kBits[p];
    std::uint32_t* h = hist[p];
    if (n > 0 && h[(from[0].bits >> kShift[p]) & (buckets - 1)] == n) continue;
    std::uint32_t sum = 0;
    for (std::size_t d = 0; d < buckets; ++d) sum += std::exchange(h[d], sum);
    for (std::size_t i = 0; i < n; ++i) {
      const Event e = from[i];
      to[h[(e.bits >> kShift[p]) & (buckets - 1)]++] = e;
    }
    std::swap(from, to);
    moved += n;
  }
  if (from != data) std::copy(from, from + n, data);
  return moved;
}

template <class Lists>
void push_events(const Aabb& b, std::uint32_t local, Lists& lists) {
  for (int axis = 0; axis < 3; ++axis) {
    if (b.min[axis] == b.max[axis]) {
      lists[std::size_t(axis)].push_back(make_event(b.min[axis], kPlanar, local));
    } else {
      lists[std::size_t(axis)].push_back(make_event(b.min[axis], kStart, local));
      lists[std::size_t(axis)].push_back(make_event(b.max[axis], kEnd, local));
    }
  }
}

/// The SAH cost of a plane, the options' three constants held by value (read through the
/// options reference, they were loaded again at every position of a sweep).
struct Sah {
  float traversal, intersection, empty_bonus;
  // Counts are signed 32-bit here: their conversion to float is one instruction.
  [[nodiscard]] float operator()(float p_below, float p_above, std::int32_t n_below,
                                 std::int32_t n_above) const {
    const float cost =
        traversal + intersection * (p_below * float(n_below) + p_above * float(n_above));
    return (n_below == 0 || n_above == 0) ? empty_bonus * cost : cost;
  }
};

/// One axis's sweep: the node's extent along it, the areas' terms and the cost's constants.
struct SweepFrame {
  float lo, hi;    ///< the box along the axis
  float cap;       ///< the area of the box's face across the axis
  float perimeter; ///< half the perimeter of that face
  float inv_area;  ///< 1 / the box's half area
  std::int32_t n;  ///< the node's triangles
  Sah sah;
};

/// Where a sweep stands between two positions: the triangles below and above the next one, and
/// the best plane so far.
struct SweepState {
  std::int32_t n_below = 0, n_above = 0;
  float best_cost = kInf, best_pos = 0.0f;
  bool best_planar_below = true;
};

/// Event lists at least this long are swept eight events at a time (shorter ones: the blocks'
/// set-up and the final reduction would cost more than they save).
constexpr std::size_t kSimdSweepMin = 32;

struct Split {
  float cost = kInf;
  int axis = -1;
  float pos = 0.0f;
  bool planar_below = true; ///< the side that takes the triangles lying in the plane
};

/// Nodes of at most this many triangles are built from their triangles' boxes (SmallNode) where
/// AVX2 runs. Measured on the bunny x2 (one core, same trees): 8 builds 1.12x as fast as the
/// event lists alone, 16 another 1.09x, 24 and 32 no faster than 16.
constexpr std::uint32_t kSmallNode = 16;

/// A node of at most kSmallNode triangles as its triangles' boxes: on each axis the positions its
/// events would hold (min == max: the triangle lies in a plane of the axis). Lanes from n on hold
/// +inf, which no count and no candidate plane takes up. Its splits classify and copy a few boxes
/// instead of filtering, sorting and merging three event lists.
struct SmallNode {
  Aabb box;
  std::uint32_t n = 0;
  std::array<std::uint32_t, kSmallNode> tris{}; ///< ascending, as the node's list
  alignas(32) float min[3][kSmallNode];
  alignas(32) float max[3][kSmallNode];
};

namespace sweep_avx2 {

#define SPECULA_SWEEP_TARGET __attribute__((target("avx2")))

/// x shifted up the lanes by the permutation `idx`, the lanes below `keep` zeroed.
SPECULA_SWEEP_TARGET inline __m256i up(__m256i x, __m256i idx, __m256i keep) {
  return _mm256_and_si256(_mm256_permutevar8x32_epi32(x, idx), keep);
}

/// The SAH cost of eight planes, with Sah's operations in its order (no fused multiply-add: the
/// function's target does not allow one), so each lane is the scalar cost to the bit.
SPECULA_SWEEP_TARGET inline __m256 sah8(__m256 p_below, __m256 p_above, __m256i n_below,
                                        __m256i n_above, __m256 traversal, __m256 intersection,
                                        __m256 bonus) {
  const __m256 sum = _mm256_add_ps(_mm256_mul_ps(p_below, _mm256_cvtepi32_ps(n_below)),
                                   _mm256_mul_ps(p_above, _mm256_cvtepi32_ps(n_above)));
  const __m256 cost = _mm256_add_ps(traversal, _mm256_mul_ps(intersection, sum));
  const __m256i zero = _mm256_setzero_si256();
  const __m256i empty =
      _mm256_or_si256(_mm256_cmpeq_epi32(n_below, zero), _mm256_cmpeq_epi32(n_above, zero));
  return _mm256_blendv_ps(cost, _mm256_mul_ps(bonus, cost), _mm256_castsi256_ps(empty));
}

/// A SweepFrame in every lane.
struct Frame8 {
  __m256 lo, hi, cap, perimeter, inv_area, traversal, intersection, bonus;
  __m256i n;
};
SPECULA_SWEEP_TARGET inline Frame8 frame8(const SweepFrame& f) {
  return {_mm256_set1_ps(f.lo),
          _mm256_set1_ps(f.hi),
          _mm256_set1_ps(f.cap),
          _mm256_set1_ps(f.perimeter),
          _mm256_set1_ps(f.inv_area),
          _mm256_set1_ps(f.sah.traversal),
          _mm256_set1_ps(f.sah.intersection),
          _mm256_set1_ps(f.sah.empty_bonus),
          _mm256_set1_epi32(f.n)};
}

/// The two costs of eight candidate planes, as the scalar sweep weighs them at a position:
/// `below` with the planar triangles below (inside the box, or in its lower face when there are
/// any), `above` with them above (inside, or in its upper face, only where there are any), each
/// valid in the lanes where the scalar sweep weighs it.
struct Costs8 {
  __m256 below, above;
  __m256i below_valid, above_valid; ///< above_valid all zero when no lane weighs `above`
};

/// The costs at positions p (lanes in `candidate`), given the triangles before each position
/// (starts and planar ones), those lying in it, and those not ended at or before it.
SPECULA_SWEEP_TARGET inline Costs8 weigh(const Frame8& f, __m256 p, __m256i candidate,
                                         __m256i before, __m256i planar, __m256i n_above) {
  const __m256 p_below = _mm256_mul_ps(
      _mm256_add_ps(f.cap, _mm256_mul_ps(_mm256_sub_ps(p, f.lo), f.perimeter)), f.inv_area);
  const __m256 p_above = _mm256_mul_ps(
      _mm256_add_ps(f.cap, _mm256_mul_ps(_mm256_sub_ps(f.hi, p), f.perimeter)), f.inv_area);
  const __m256i inside = _mm256_castps_si256(
      _mm256_and_ps(_mm256_cmp_ps(p, f.lo, _CMP_GT_OQ), _mm256_cmp_ps(p, f.hi, _CMP_LT_OQ)));
  const __m256i at_lo = _mm256_castps_si256(_mm256_cmp_ps(p, f.lo, _CMP_EQ_OQ));
  const __m256i has_planar =
      _mm256_and_si256(candidate, _mm256_cmpgt_epi32(planar, _mm256_setzero_si256()));
  Costs8 c;
  c.below_valid =
      _mm256_and_si256(candidate, _mm256_or_si256(inside, _mm256_and_si256(has_planar, at_lo)));
  c.below =
      sah8(p_below, p_above, _mm256_blendv_epi8(planar, _mm256_add_epi32(before, planar), inside),
           n_above, f.traversal, f.intersection, f.bonus);
  c.above_valid = _mm256_setzero_si256();
  c.above = c.below;
  if (!_mm256_testz_si256(has_planar, has_planar)) {
    c.above_valid = _mm256_andnot_si256(_mm256_andnot_si256(inside, at_lo), has_planar);
    c.above = sah8(p_below, p_above, before,
                   _mm256_blendv_epi8(planar, _mm256_add_epi32(n_above, planar), inside),
                   f.traversal, f.intersection, f.bonus);
  }
  return c;
}

/// Per lane, `cost` and `index` become the best where `valid` and strictly below the best so far
/// (a lane keeps its first best, as the scalar sweep does).
SPECULA_SWEEP_TARGET inline void keep_better(__m256i valid, __m256 cost, __m256i index,
                                             __m256& best, __m256i& best_index) {
  const __m256i take =
      _mm256_and_si256(valid, _mm256_castps_si256(_mm256_cmp_ps(cost, best, _CMP_LT_OQ)));
  best = _mm256_blendv_ps(best, cost, _mm256_castsi256_ps(take));
  best_index = _mm256_blendv_epi8(best_index, index, take);
}

/// The sweep over e[0, m) eight events at a time, lane i of a block holding event i: per lane,
/// the counts by type before it (prefix sums), whether it is its position's last event (the next
/// key differs), and the counts before its position's first event (carried up to it by a max-scan,
/// the counts being non-decreasing); at a position's last event, the plane's costs as the scalar
/// sweep weighs them there. Each lane keeps its first best; the lanes' bests are then reduced to
/// the first best of all in list order (its index is 2·event, +1 for the cost with the planar
/// triangles above), which is what the scalar sweep's strict comparisons keep. Stops before the
/// last block (a block reads the key after it) and returns the first event of the position that
/// block ends in, with `st` as the scalar sweep has it there; the scalar sweep goes on from it.
SPECULA_SWEEP_TARGET std::size_t blocks(const Event* e, std::size_t m, const SweepFrame& f,
                                        SweepState& st) {
  const __m256i ones = _mm256_set1_epi32(1), all = _mm256_set1_epi32(-1);
  const __m256i idx_next = _mm256_setr_epi32(1, 2, 3, 4, 5, 6, 7, 7);
  const __m256i idx_up1 = _mm256_setr_epi32(0, 0, 1, 2, 3, 4, 5, 6);
  const __m256i idx_up2 = _mm256_setr_epi32(0, 0, 0, 1, 2, 3, 4, 5);
  const __m256i idx_up4 = _mm256_setr_epi32(0, 0, 0, 0, 0, 1, 2, 3);
  const __m256i keep1 = _mm256_setr_epi32(0, -1, -1, -1, -1, -1, -1, -1);
  const __m256i keep2 = _mm256_setr_epi32(0, 0, -1, -1, -1, -1, -1, -1);
  const __m256i keep4 = _mm256_setr_epi32(0, 0, 0, 0, -1, -1, -1, -1);
  const __m256i lane2 = _mm256_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14);
  const __m256i field = _mm256_set1_epi32(1023);
  const __m256i sign = _mm256_set1_epi32(std::int32_t(0x80000000u));
  const Frame8 f8 = frame8(f);

  __m256 best = _mm256_set1_ps(kInf);
  __m256i best_index = _mm256_setzero_si256();
  const __m256i idx_last = _mm256_set1_epi32(7);
  // Never a count: the max-scans' value for lanes whose position began before the block.
  const __m256i none = _mm256_set1_epi32(-(1 << 30));
  // Counts by type of the events before the block, and of those before the position the
  // previous block ended in (that position may go on into this block), in every lane: the
  // carries stay in vector registers, one permutation from block to block.
  __m256i ends = _mm256_setzero_si256(), planars = ends, starts = ends;
  __m256i open_starts = ends, open_planars = ends;
  std::uint32_t prev_key = ~e[0].pos_key(); // differs from the first key
  std::size_t i = 0;
  for (; i + 8 < m; i += 8) {
    const __m256 a = _mm256_loadu_ps(reinterpret_cast<const float*>(e + i));
    const __m256 b = _mm256_loadu_ps(reinterpret_cast<const float*>(e + i + 4));
    // High words (keys) and low words (type and triangle) of the eight events, in order.
    const __m256i key = _mm256_permute4x64_epi64(
        _mm256_castps_si256(_mm256_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1))), 0xD8);
    const __m256i low = _mm256_permute4x64_epi64(
        _mm256_castps_si256(_mm256_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0))), 0xD8);
    const __m256i type = _mm256_srli_epi32(low, 30);
    const __m256i next =
        _mm256_blend_epi32(_mm256_permutevar8x32_epi32(key, idx_next),
                           _mm256_set1_epi32(std::int32_t(e[i + 8].pos_key())), 0x80);
    const __m256i prev = _mm256_blend_epi32(_mm256_permutevar8x32_epi32(key, idx_up1),
                                            _mm256_set1_epi32(std::int32_t(prev_key)), 0x01);
    const __m256i last = _mm256_xor_si256(_mm256_cmpeq_epi32(key, next), all);
    const __m256i first = _mm256_xor_si256(_mm256_cmpeq_epi32(key, prev), all);
    // The three counts packed ten bits apart (a block adds at most 8 to each), summed up the
    // lanes in three steps.
    __m256i x = _mm256_sllv_epi32(
        ones, _mm256_add_epi32(_mm256_slli_epi32(type, 3), _mm256_slli_epi32(type, 1)));
    x = _mm256_add_epi32(x, up(x, idx_up1, keep1));
    x = _mm256_add_epi32(x, up(x, idx_up2, keep2));
    x = _mm256_add_epi32(x, up(x, idx_up4, keep4));
    const __m256i e_local = _mm256_and_si256(x, field);
    const __m256i p_local = _mm256_and_si256(_mm256_srli_epi32(x, 10), field);
    const __m256i s_local = _mm256_srli_epi32(x, 20);
    const __m256i is_start = _mm256_and_si256(_mm256_cmpeq_epi32(type, _mm256_set1_epi32(2)), ones);
    const __m256i is_planar = _mm256_and_si256(_mm256_cmpeq_epi32(type, ones), ones);
    // Starts and planar events before each lane's position within the block: the exclusive
    // counts at the position's first event, carried up the lanes by a max-scan (the counts do not
    // decrease; a lane's permutation source below it is in its own prefix, so no lane needs
    // masking). Lanes whose position began before the block keep `none`.
    __m256i s_scan = _mm256_blendv_epi8(none, _mm256_sub_epi32(s_local, is_start), first);
    __m256i p_scan = _mm256_blendv_epi8(none, _mm256_sub_epi32(p_local, is_planar), first);
    s_scan = _mm256_max_epi32(s_scan, _mm256_permutevar8x32_epi32(s_scan, idx_up1));
    p_scan = _mm256_max_epi32(p_scan, _mm256_permutevar8x32_epi32(p_scan, idx_up1));
    s_scan = _mm256_max_epi32(s_scan, _mm256_permutevar8x32_epi32(s_scan, idx_up2));
    p_scan = _mm256_max_epi32(p_scan, _mm256_permutevar8x32_epi32(p_scan, idx_up2));
    s_scan = _mm256_max_epi32(s_scan, _mm256_permutevar8x32_epi32(s_scan, idx_up4));
    p_scan = _mm256_max_epi32(p_scan, _mm256_permutevar8x32_epi32(p_scan, idx_up4));
    // The carries added last: the scans above do not wait for the previous block.
    const __m256i e_incl = _mm256_add_epi32(e_local, ends);
    const __m256i p_incl = _mm256_add_epi32(p_local, planars);
    const __m256i s_incl = _mm256_add_epi32(s_local, starts);
    const __m256i s_before = _mm256_max_epi32(_mm256_add_epi32(s_scan, starts), open_starts);
    const __m256i p_before = _mm256_max_epi32(_mm256_add_epi32(p_scan, planars), open_planars);

    const __m256i n_above = _mm256_sub_epi32(_mm256_sub_epi32(f8.n, e_incl), p_incl);
    const __m256i planar = _mm256_sub_epi32(p_incl, p_before);
    // The position from its key (from_ordered_key, lane by lane).
    const __m256 p = _mm256_castsi256_ps(_mm256_xor_si256(
        key, _mm256_or_si256(_mm256_andnot_si256(_mm256_srai_epi32(key, 31), all), sign)));
    const __m256i index = _mm256_add_epi32(_mm256_set1_epi32(std::int32_t(2 * i)), lane2);
    const Costs8 c = weigh(f8, p, last, _mm256_add_epi32(s_before, p_before), planar, n_above);
    keep_better(c.below_valid, c.below, index, best, best_index);
    if (!_mm256_testz_si256(c.above_valid, c.above_valid)) // rarely: planar triangles
      keep_better(c.above_valid, c.above, _mm256_add_epi32(index, ones), best, best_index);
    ends = _mm256_permutevar8x32_epi32(e_incl, idx_last);
    planars = _mm256_permutevar8x32_epi32(p_incl, idx_last);
    starts = _mm256_permutevar8x32_epi32(s_incl, idx_last);
    open_starts = _mm256_permutevar8x32_epi32(s_before, idx_last);
    open_planars = _mm256_permutevar8x32_epi32(p_before, idx_last);
    prev_key = e[i + 7].pos_key();
  }

  // The lanes' bests reduced to the first best in list order.
  alignas(32) float cost[8];
  alignas(32) std::int32_t index[8];
  _mm256_store_ps(cost, best);
  _mm256_store_si256(reinterpret_cast<__m256i*>(index), best_index);
  int winner = -1;
  for (int l = 0; l < 8; ++l) {
    if (!(cost[l] < kInf)) continue;
    if (winner < 0 || cost[l] < cost[winner] ||
        (cost[l] == cost[winner] && index[l] < index[winner]))
      winner = l;
  }
  if (winner >= 0) {
    st.best_cost = cost[winner];
    st.best_pos = e[std::size_t(index[winner]) / 2].pos();
    st.best_planar_below = (index[winner] & 1) == 0;
  }
  // Back to the first event of the position the last block ended in, with the counts before it.
  std::int32_t n_ends = _mm256_cvtsi256_si32(ends), n_planars = _mm256_cvtsi256_si32(planars),
               n_starts = _mm256_cvtsi256_si32(starts);
  std::size_t g = i;
  while (g > 0 && e[g - 1].pos_key() == e[i].pos_key()) {
    --g;
    const std::uint32_t t = e[g].type();
    n_ends -= std::int32_t(t == kEnd);
    n_planars -= std::int32_t(t == kPlanar);
    n_starts -= std::int32_t(t == kStart);
  }
  st.n_below = n_starts + n_planars;
  st.n_above = f.n - n_ends - n_planars;
  return g;
}

/// Lanes where (cost, pos, variant) comes first in the scalar sweep's order: a lower cost, or the
/// same cost at a lower position, or at the same position the planar triangles below (variant 0)
/// before above (1).
SPECULA_SWEEP_TARGET inline __m256 comes_first(__m256 cost, __m256 pos, __m256i variant,
                                               __m256 best, __m256 best_pos, __m256i best_variant) {
  return _mm256_or_ps(
      _mm256_cmp_ps(cost, best, _CMP_LT_OQ),
      _mm256_and_ps(_mm256_cmp_ps(cost, best, _CMP_EQ_OQ),
                    _mm256_or_ps(_mm256_cmp_ps(pos, best_pos, _CMP_LT_OQ),
                                 _mm256_and_ps(_mm256_cmp_ps(pos, best_pos, _CMP_EQ_OQ),
                                               _mm256_castsi256_ps(
                                                   _mm256_cmpgt_epi32(best_variant, variant))))));
}

/// Per lane, (cost, pos, variant) becomes the best where `valid`, finite and first.
SPECULA_SWEEP_TARGET inline void keep_first(__m256i valid, __m256 cost, __m256 pos,
                                            std::int32_t variant, __m256& best, __m256& best_pos,
                                            __m256i& best_variant) {
  const __m256i v = _mm256_set1_epi32(variant);
  const __m256 take =
      _mm256_and_ps(_mm256_and_ps(_mm256_castsi256_ps(valid),
                                  comes_first(cost, pos, v, best, best_pos, best_variant)),
                    _mm256_cmp_ps(cost, _mm256_set1_ps(kInf), _CMP_LT_OQ));
  best = _mm256_blendv_ps(best, cost, take);
  best_pos = _mm256_blendv_ps(best_pos, pos, take);
  best_variant = _mm256_blendv_epi8(best_variant, v, _mm256_castps_si256(take));
}

/// The first of the eight lanes' bests, in every lane (three steps, each lane against a partner).
SPECULA_SWEEP_TARGET inline void first_of_lanes(__m256& best, __m256& best_pos,
                                                __m256i& best_variant) {
  const __m256i partners[3] = {_mm256_setr_epi32(4, 5, 6, 7, 0, 1, 2, 3),
                               _mm256_setr_epi32(2, 3, 0, 1, 6, 7, 4, 5),
                               _mm256_setr_epi32(1, 0, 3, 2, 5, 4, 7, 6)};
  for (const __m256i& partner : partners) {
    const __m256 cost = _mm256_permutevar8x32_ps(best, partner);
    const __m256 pos = _mm256_permutevar8x32_ps(best_pos, partner);
    const __m256i variant = _mm256_permutevar8x32_epi32(best_variant, partner);
    const __m256 take = comes_first(cost, pos, variant, best, best_pos, best_variant);
    best = _mm256_blendv_ps(best, cost, take);
    best_pos = _mm256_blendv_ps(best_pos, pos, take);
    best_variant = _mm256_blendv_epi8(best_variant, variant, _mm256_castps_si256(take));
  }
}

/// The sweep of a SmallNode's axis: every position a triangle's box starts or ends at is a
/// candidate (a lane; eight at a time, or up to four triangles' starts and ends at once), the
/// counts the scalar sweep has there taken over the n triangles (below it: the boxes starting
/// below; above it: those not ending at or below it; in it: the flat ones there), and the costs
/// weighed as the scalar sweep weighs them. The first best in the scalar sweep's order is kept
/// (keep_first), so the plane is the one the event lists would give.
SPECULA_SWEEP_TARGET Split small(const float* min, const float* max, std::uint32_t n,
                                 const SweepFrame& f, int axis) {
  const Frame8 f8 = frame8(f);
  const __m256i all = _mm256_set1_epi32(-1);
  __m256 best = _mm256_set1_ps(kInf), best_pos = best;
  __m256i best_variant = _mm256_setzero_si256();
  // The candidates: the boxes' starts, then their ends; up to four triangles, both in one vector.
  const std::uint32_t blocks = (n + 7) / 8;
  const int passes = n <= 4 ? 1 : 2 * int(blocks);
  for (int pass = 0; pass < passes; ++pass) {
    const __m256 p =
        passes == 1
            ? _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(min)), _mm_load_ps(max), 1)
            : _mm256_load_ps((pass < int(blocks) ? min : max) + 8 * (pass % int(blocks)));
    __m256i below = _mm256_setzero_si256(), ended = below, planar = below;
    for (std::uint32_t j = 0; j < n; ++j) {
      const __m256 mn = _mm256_set1_ps(min[j]), mx = _mm256_set1_ps(max[j]);
      below = _mm256_sub_epi32(below, _mm256_castps_si256(_mm256_cmp_ps(mn, p, _CMP_LT_OQ)));
      ended = _mm256_sub_epi32(ended, _mm256_castps_si256(_mm256_cmp_ps(mx, p, _CMP_LE_OQ)));
      // Flat boxes (min == max) at the candidate: its triangles lying in the plane.
      planar = _mm256_sub_epi32(
          planar, _mm256_castps_si256(_mm256_and_ps(_mm256_cmp_ps(mn, mx, _CMP_EQ_OQ),
                                                    _mm256_cmp_ps(mn, p, _CMP_EQ_OQ))));
    }
    const Costs8 c = weigh(f8, p, all, below, planar, _mm256_sub_epi32(f8.n, ended));
    keep_first(c.below_valid, c.below, p, 0, best, best_pos, best_variant);
    if (!_mm256_testz_si256(c.above_valid, c.above_valid))
      keep_first(c.above_valid, c.above, p, 1, best, best_pos, best_variant);
  }
  first_of_lanes(best, best_pos, best_variant);
  Split result;
  const float cost = _mm256_cvtss_f32(best);
  if (cost < kInf)
    result = {cost, axis, _mm256_cvtss_f32(best_pos), _mm256_cvtsi256_si32(best_variant) == 0};
  return result;
}

#undef SPECULA_SWEEP_TARGET

} // namespace sweep_avx2

class Builder {
public:
  Builder(const TriangleView& tris, const KdBuildOptions& options, std::uint32_t max_depth)
      : tris_(tris), options_(options), max_depth_(max_depth),
        simd_(options.simd && cpu_has_avx2()) {}

  /// Builds `in` at `depth`, appending its subtree (depth first) to `out`.
  void build(NodeInput&& in, std::uint32_t depth, Subtree& out, Scratch& scratch) const {
    if (simd_ && in.tris.size() <= kSmallNode) {
      build_small(small_node(in), depth, out);
      return;
    }
    Counters& c = out.counters;
    c.max_depth = std::max(c.max_depth, depth);
    const std::size_t n = in.tris.size();
    c.events += in.events[0].size() + in.events[1].size() + in.events[2].size();
    const float area = half_area(in.box.extent());
    const std::size_t node = out.nodes.size();
    out.nodes.push_back({});

    Split split;
    if (n > options_.leaf_size && depth < max_depth_ && area > 0.0f) split = find_split(in, n);
    if (split.axis < 0 || !(split.cost < options_.intersection_cost * float(n))) {
      make_leaf(in, area, out, node);
      return;
    }

    // Small nodes take their children's lists from the task's arena, back once both subtrees
    // are built (the node's own lists, made by its parent before this mark, stay until the
    // parent releases). Large ones put them on the heap and free their own before building the
    // children, so that the largest lists are never held along the whole path.
    const Arena::Mark mark = scratch.arena.mark();
    NodeInput below, above;
    // A cut off empty space is known from the ends of the split axis's list; only a cut through
    // the triangles classifies them.
    Sides sides = one_sided(in, split);
    if (sides == Sides::kBoth) {
      sides = split_node(in, split, below, above, c, scratch,
                         n >= kHeapLists ? nullptr : &scratch.arena);
    } else {
#ifndef NDEBUG
      Counters ignored;
      SPECULA_ASSERT(split_node(in, split, below, above, ignored, scratch, &scratch.arena) ==
                     sides);
#endif
      below.box = in.box;
      below.box.max[split.axis] = split.pos;
      above.box = in.box;
      above.box.min[split.axis] = split.pos;
    }
    if (sides != Sides::kBoth) {
      // A cut that leaves one side empty (most splits of a deep tree: each empty leaf is one):
      // every triangle is on the other side, with the same local index, so that child's lists
      // are the node's own, event for event. They are handed over instead of filtered and copied.
      NodeInput& full = sides == Sides::kAllBelow ? below : above;
      full.tris = std::move(in.tris);
      full.events = std::move(in.events);
    }
    in = NodeInput{};
    c.sah += double(options_.traversal_cost) * double(area);

    std::size_t above_index;
    if (options_.parallel && n >= kParallelChildren) {
      // The child below comes first in the array, so it appends straight to `out`; only the one
      // above builds into its own arrays, spliced after.
      Subtree sub_above;
      Scratch scratch_above;
      tbb::parallel_invoke([&] { build(std::move(below), depth + 1, out, scratch); },
                           [&] { build(std::move(above), depth + 1, sub_above, scratch_above); });
      above_index = out.nodes.size();
      splice(out, sub_above);
    } else {
      build(std::move(below), depth + 1, out, scratch);
      above_index = out.nodes.size();
      build(std::move(above), depth + 1, out, scratch);
    }
    scratch.arena.release(mark);
    if (above_index >= kMaxTriangles) throw std::length_error("kd-tree: too many nodes");
    out.nodes[node].bits = (std::uint32_t(above_index) << 2) | std::uint32_t(split.axis);
    out.nodes[node].split = split.pos;
  }

private:
  static void splice(Subtree& out, const Subtree& sub) {
    const auto node_base = std::uint32_t(out.nodes.size());
    const auto index_base = std::uint32_t(out.indices.size());
    for (gpu::KdNode n : sub.nodes) {
      if ((n.bits & 3u) == gpu::kKdLeaf)
        n.first += index_base;
      else
        n.bits += node_base << 2;
      out.nodes.push_back(n);
    }
    out.indices.insert(out.indices.end(), sub.indices.begin(), sub.indices.end());
    out.counters.add(sub.counters);
  }

  void make_leaf(const NodeInput& in, float area, Subtree& out, std::size_t node) const {
    make_leaf(in.tris.data(), std::uint32_t(in.tris.size()), area, out, node);
  }
  void make_leaf(const std::uint32_t* tris, std::uint32_t n, float area, Subtree& out,
                 std::size_t node) const {
    Counters& c = out.counters;
    out.nodes[node].bits = (n << 2) | gpu::kKdLeaf;
    out.nodes[node].first = std::uint32_t(out.indices.size());
    out.indices.insert(out.indices.end(), tris, tris + n);
    ++c.leaves;
    if (n == 0) ++c.empty_leaves;
    c.references += n;
    c.sah += double(options_.intersection_cost) * double(n) * double(area);
  }

  /// The sweep's terms for `axis` of a node with box `box` and n triangles.
  [[nodiscard]] SweepFrame frame(const Aabb& box, int axis, std::size_t n) const {
    const vec3 extent = box.extent();
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    return {box.min[axis],
            box.max[axis],
            extent[u] * extent[v],
            extent[u] + extent[v],
            1.0f / half_area(extent),
            std::int32_t(n),
            {options_.traversal_cost, options_.intersection_cost, options_.empty_bonus}};
  }

  /// The sweep of Wald & Havran §5.1 over one axis's sorted events: the best plane inside the box,
  /// or in one of its faces when triangles lie in that face (they go to a flat cell; a face plane
  /// cuts nothing else off).
  [[nodiscard]] Split sweep(const NodeInput& in, int axis, std::size_t n) const {
    Split best;
    if (!(in.box.max[axis] > in.box.min[axis])) return best;
    const SweepFrame f = frame(in.box, axis, n);
    const float lo = f.lo, hi = f.hi, cap = f.cap, perimeter = f.perimeter, inv_area = f.inv_area;
    const Sah& sah = f.sah;
    const EventList& ev = in.events[std::size_t(axis)];
    const Event* e = ev.data();
    const std::size_t m = ev.size();
    // The state in registers (the Split is written once, at the end).
    SweepState st;
    st.n_above = std::int32_t(n);
    std::size_t i = 0;
    if (simd_ && m >= kSimdSweepMin && m < (std::size_t(1) << 30))
      i = sweep_avx2::blocks(e, m, f, st);
    std::int32_t n_below = st.n_below, n_above = st.n_above;
    float best_cost = st.best_cost, best_pos = st.best_pos;
    bool best_planar_below = st.best_planar_below;
    while (i < m) {
      // The events at one position, counted by type (the list is sorted end < planar < start),
      // without indexing an array by the type: the counts stay in registers.
      const std::uint32_t pk = e[i].pos_key();
      const float p = from_ordered_key(pk);
      std::int32_t ending = 0, planar = 0, starting = 0;
      do {
        const std::uint32_t type = e[i].type();
        ending += std::int32_t(type == kEnd);
        planar += std::int32_t(type == kPlanar);
        starting += std::int32_t(type == kStart);
        ++i;
      } while (i < m && e[i].pos_key() == pk);
      n_above -= planar + ending;
      const float p_below = (cap + (p - lo) * perimeter) * inv_area;
      const float p_above = (cap + (hi - p) * perimeter) * inv_area;
      if (p > lo && p < hi) {
        const float cost_below = sah(p_below, p_above, n_below + planar, n_above);
        if (cost_below < best_cost) {
          best_cost = cost_below;
          best_pos = p;
          best_planar_below = true;
        }
        // Without triangles in the plane (nearly every position) the other side's cost is the
        // same number, which never wins a strict comparison: it is not computed.
        if (planar == 0) {
          n_below += starting;
          continue;
        }
        const float cost_above = sah(p_below, p_above, n_below, n_above + planar);
        if (cost_above < best_cost) {
          best_cost = cost_above;
          best_pos = p;
          best_planar_below = false;
        }
      } else if (planar > 0) {
        // Triangles lying in a face of the box (a floor, a wall) split off into a flat cell of
        // their own; otherwise every cell along that face keeps them.
        const bool at_lo = p == lo;
        const float cost = at_lo ? sah(p_below, p_above, planar, n_above)
                                 : sah(p_below, p_above, n_below, planar);
        if (cost < best_cost) {
          best_cost = cost;
          best_pos = p;
          best_planar_below = at_lo;
        }
      }
      n_below += starting + planar;
    }
    if (best_cost < kInf) best = {best_cost, axis, best_pos, best_planar_below};
    return best;
  }

  [[nodiscard]] Split find_split(const NodeInput& in, std::size_t n) const {
    std::array<Split, 3> s;
    if (options_.parallel && n >= kParallelAxes) {
      tbb::parallel_invoke([&] { s[0] = sweep(in, 0, n); }, [&] { s[1] = sweep(in, 1, n); },
                           [&] { s[2] = sweep(in, 2, n); });
    } else {
      for (int a = 0; a < 3; ++a) s[std::size_t(a)] = sweep(in, a, n);
    }
    Split best = s[0]; // ties go to the lower axis
    for (std::size_t a = 1; a < 3; ++a)
      if (s[a].cost < best.cost) best = s[a];
    return best;
  }

  enum Side : std::uint8_t { kBoth = 0, kBelowOnly = 1, kAboveOnly = 2 };

  /// Where split_node's classification put the node's triangles.
  enum class Sides { kBoth, kAllBelow, kAllAbove };

  /// The bounds of a straddling triangle's parts in the two children (parts[0] below, parts[1]
  /// above): its part in the node, clipped once and split by the plane (the same polygons as
  /// clipping to each child's box, with one pass over the node's planes instead of two).
  void straddler_parts(std::uint32_t prim, const Aabb& node_box, const Split& split,
                       const Aabb& below_box, const Aabb& above_box, Aabb parts[2]) const {
    const vec3 v0 = tris_.vertex(prim, 0), v1 = tris_.vertex(prim, 1), v2 = tris_.vertex(prim, 2);
    Aabb whole; // tris_.bounds(prim), from the vertices already read
    whole.grow(v0);
    whole.grow(v1);
    whole.grow(v2);
    std::array<vec3, kMaxPolygon> in_node, part_below, part_above;
    int n_part[2] = {0, 0};
    if (options_.perfect_splits) {
      const int m = clip_to_box(v0, v1, v2, whole, node_box, in_node.data());
      if (m > 0) {
        n_part[0] = clip_polygon(in_node.data(), m, split.axis, split.pos, true, part_below.data());
        n_part[1] =
            clip_polygon(in_node.data(), m, split.axis, split.pos, false, part_above.data());
      }
    }
    for (int child = 0; child < 2; ++child) {
      const Aabb& box = child == 0 ? below_box : above_box;
      if (!polygon_bounds(child == 0 ? part_below.data() : part_above.data(), n_part[child], whole,
                          box, parts[child])) {
        // No clipping, or clipping lost the sliver to rounding or gave up: the triangle's box
        // cut to the child box, never empty for a triangle that straddles the plane.
        parts[child].min = glm::max(whole.min, box.min);
        parts[child].max = glm::min(whole.max, box.max);
      }
    }
  }

  /// Whether the split's plane leaves every triangle on one side, from the ends of its axis's
  /// sorted list alone (a cut off empty space: most splits of a deep tree): the classification's
  /// answer without classifying. At the plane's position the types sort end < planar < start, and
  /// a triangle with a start there ends beyond it.
  [[nodiscard]] static Sides one_sided(const NodeInput& in, const Split& split) {
    const EventList& events = in.events[std::size_t(split.axis)];
    const std::uint32_t at = ordered_key(split.pos);
    const Event& last = events[events.size() - 1];
    if (last.pos_key() < at ||
        (last.pos_key() == at &&
         (last.type() == kEnd || (last.type() == kPlanar && split.planar_below))))
      return Sides::kAllBelow;
    const Event& first = events[0];
    if (first.pos_key() > at ||
        (first.pos_key() == at &&
         (first.type() == kStart || (first.type() == kPlanar && !split.planar_below))))
      return Sides::kAllAbove;
    return Sides::kBoth;
  }

  /// Classification, list split and the straddling triangles' new events (Wald & Havran §5.2–5.3),
  /// all linear in the node's events but for the sort of the new events. Sets both children's
  /// boxes; when every triangle lies on one side (kAllBelow, kAllAbove) it stops after the
  /// classification and leaves both children's lists empty: the caller hands the node's own
  /// lists to the full side.
  [[nodiscard]] Sides split_node(const NodeInput& in, const Split& split, NodeInput& below,
                                 NodeInput& above, Counters& c, Scratch& scratch,
                                 Arena* arena) const {
    const std::size_t n = in.tris.size();
    const auto axis = std::size_t(split.axis);
    // Classification without branches: a triangle gets at most one of the two flags (an end at or
    // below the plane means its start lies below it; planar events are one or the other). The
    // list is sorted, so it falls into three runs (positions below, at and above the plane), and
    // within each run an event's flag depends on its type alone.
    std::vector<std::uint8_t>& side = scratch.side;
    side.assign(n, kBoth);
    {
      const EventList& events = in.events[axis];
      const std::uint64_t at = std::uint64_t(ordered_key(split.pos)) << 32;
      const Event* first = events.begin();
      const Event* last = events.end();
      const Event* mid = std::lower_bound(first, last, Event{at});
      const Event* high = std::lower_bound(mid, last, Event{at + (std::uint64_t(1) << 32)});
      std::uint8_t* sd = side.data();
      // Below the plane: ends and planar events are below, starts say nothing.
      for (const Event* e = first; e != mid; ++e)
        sd[e->local()] |= std::uint8_t(e->type() != kStart);
      // In the plane: ends below, starts above, planar events on the split's side for them.
      const std::uint8_t flag[3] = {kBelowOnly, split.planar_below ? kBelowOnly : kAboveOnly,
                                    kAboveOnly}; // by type: end, planar, start
      for (const Event* e = mid; e != high; ++e) sd[e->local()] |= flag[e->type()];
      // Above the plane: starts and planar events are above, ends say nothing.
      for (const Event* e = high; e != last; ++e)
        sd[e->local()] |= std::uint8_t(std::uint32_t(e->type() != kEnd) << 1);
    }

    // New local indices keep the old order, so the filtered lists stay sorted.
    std::size_t n_below = 0, n_above = 0, n_both = 0;
    for (std::size_t l = 0; l < n; ++l) {
      n_below += side[l] != kAboveOnly;
      n_above += side[l] != kBelowOnly;
      n_both += side[l] == kBoth;
    }
    below.box = in.box;
    below.box.max[split.axis] = split.pos;
    above.box = in.box;
    above.box.min[split.axis] = split.pos;
    if (n_above == 0) return Sides::kAllBelow;
    if (n_below == 0) return Sides::kAllAbove;

    std::vector<std::uint32_t>& remap = scratch.remap; // the index in its child (below if both)
    std::vector<std::uint32_t>& straddling = scratch.straddling;
    std::vector<std::uint32_t>& above_index = scratch.above_index; // a straddler's index above
    // Without branches on the side (its outcome is data): every triangle is written to each list
    // and the write positions advance only on its sides, so each list has room for one more.
    remap.resize(n);
    straddling.resize(n_both + 1);
    above_index.resize(n_both + 1);
    below.tris.allocate(arena, n_below + 1);
    above.tris.allocate(arena, n_above + 1);
    below.tris.set_size(n_below);
    above.tris.set_size(n_above);
    {
      std::uint32_t b = 0, a = 0, k = 0;
      std::uint32_t* bt = below.tris.data();
      std::uint32_t* at = above.tris.data();
      for (std::uint32_t l = 0; l < n; ++l) {
        const std::uint8_t sd = side[l];
        const std::uint32_t prim = in.tris[l];
        straddling[k] = l;
        above_index[k] = a;
        remap[l] = sd == kAboveOnly ? a : b;
        bt[b] = prim;
        at[a] = prim;
        k += std::uint32_t(sd == kBoth);
        b += std::uint32_t(sd != kAboveOnly);
        a += std::uint32_t(sd != kBelowOnly);
      }
    }

    // The straddling triangles' events in each child, from their parts inside the child box.
    NewEventLists& new_below = scratch.new_below;
    NewEventLists& new_above = scratch.new_above;
    for (std::size_t a = 0; a < 3; ++a) { // at most two events per straddler, child and axis
      new_below[a].prepare(2 * n_both);
      new_above[a].prepare(2 * n_both);
    }
    for (std::size_t k = 0; k < n_both; ++k) {
      const std::uint32_t l = straddling[k];
      Aabb parts[2];
      straddler_parts(in.tris[l], in.box, split, below.box, above.box, parts);
      push_events(parts[0], remap[l], new_below);
      push_events(parts[1], above_index[k], new_above);
    }
    c.events += 6 * n_both;

    // One axis: the kept events filtered straight into each child's list (every event is written
    // to both, and the write positions advance only on its side), then the sorted new events
    // merged in from the back.
    // The children's lists first, here: the arena is the task's own, not shared by the axes.
    for (std::size_t a = 0; a < 3; ++a) {
      below.events[a].allocate(arena, in.events[a].size() + new_below[a].size());
      above.events[a].allocate(arena, in.events[a].size() + new_above[a].size());
    }
    auto split_axis = [&](std::size_t a) {
      const EventList& events = in.events[a];
      NewEvents& nb = new_below[a];
      NewEvents& na = new_above[a];
      std::sort(nb.begin(), nb.end());
      std::sort(na.begin(), na.end());
      EventList& out_below = below.events[a];
      EventList& out_above = above.events[a];
      Event* ob = out_below.data();
      Event* oa = out_above.data();
      std::size_t ib = 0, ia = 0;
      const std::uint8_t* sd = side.data();
      const std::uint32_t* rm = remap.data();
      for (const Event& e : events) {
        const std::uint32_t l = e.local();
        const std::uint8_t s = sd[l];
        const Event moved{(e.bits & ~std::uint64_t(kMaxTriangles - 1)) | rm[l]};
        ob[ib] = moved;
        oa[ia] = moved;
        ib += s == kBelowOnly;
        ia += s == kAboveOnly;
      }
      out_below.set_size(merge_back(ob, ib, nb));
      out_above.set_size(merge_back(oa, ia, na));
    };
    if (options_.parallel && n >= kParallelAxes) {
      tbb::parallel_invoke([&] { split_axis(0); }, [&] { split_axis(1); }, [&] { split_axis(2); });
    } else {
      for (std::size_t a = 0; a < 3; ++a) split_axis(a);
    }
    c.events += 2 * (in.events[0].size() + in.events[1].size() + in.events[2].size());
    for (std::size_t a = 0; a < 3; ++a)
      c.sort_work += sort_cost(new_below[a].size()) + sort_cost(new_above[a].size());
    return Sides::kBoth;
  }

  /// Merges the sorted `extra` into the sorted out[0, kept) in place, from the back (out has room
  /// for both); returns the merged size. Keys are unique, so there are no ties.
  static std::size_t merge_back(Event* out, std::size_t kept, const NewEvents& extra) {
    std::size_t i = kept, j = extra.size(), k = kept + extra.size();
    // Without branches on the comparison (its outcome is data): a kept event is taken while it
    // is the larger; once none is left, the sentinel (all bits 0, below every event) is never
    // taken.
    while (j > 0) {
      const Event x = extra[j - 1];
      const Event o = i > 0 ? out[i - 1] : Event{0};
      const bool from_out = x < o;
      out[--k] = from_out ? o : x;
      i -= std::size_t(from_out);
      j -= std::size_t(!from_out);
    }
    return kept + extra.size();
  }

  // ---- Nodes of at most kSmallNode triangles, from their boxes (AVX2) ----

  /// The node's triangles' boxes, read off its event lists.
  static SmallNode small_node(const NodeInput& in) {
    SmallNode s;
    s.box = in.box;
    s.n = std::uint32_t(in.tris.size());
    std::copy(in.tris.begin(), in.tris.end(), s.tris.begin());
    for (std::size_t a = 0; a < 3; ++a) {
      std::fill(std::begin(s.min[a]), std::end(s.min[a]), kInf);
      std::fill(std::begin(s.max[a]), std::end(s.max[a]), kInf);
      for (const Event& e : in.events[a]) {
        const float p = e.pos();
        if (e.type() != kEnd) s.min[a][e.local()] = p;
        if (e.type() != kStart) s.max[a][e.local()] = p;
      }
    }
    return s;
  }

  /// build() for a small node: the same decisions on the same numbers, so the same subtree, and
  /// the same work counters as its event lists would have counted.
  void build_small(const SmallNode& in, std::uint32_t depth, Subtree& out) const {
    Counters& c = out.counters;
    c.max_depth = std::max(c.max_depth, depth);
    const std::uint32_t n = in.n;
    std::uint64_t events = 0; // the node's event lists' length
    for (int a = 0; a < 3; ++a)
      for (std::uint32_t i = 0; i < n; ++i) events += in.min[a][i] == in.max[a][i] ? 1 : 2;
    c.events += events;
    const float area = half_area(in.box.extent());
    const std::size_t node = out.nodes.size();
    out.nodes.push_back({});

    Split split;
    if (n > options_.leaf_size && depth < max_depth_ && area > 0.0f) {
      for (int a = 0; a < 3; ++a) {
        if (!(in.box.max[a] > in.box.min[a])) continue;
        const Split s = sweep_avx2::small(in.min[a], in.max[a], n, frame(in.box, a, n), a);
        if (split.axis < 0 || s.cost < split.cost) split = s; // ties go to the lower axis
      }
    }
    if (split.axis < 0 || !(split.cost < options_.intersection_cost * float(n))) {
      make_leaf(in.tris.data(), n, area, out, node);
      return;
    }

    // Classification as split_node's, by the boxes: a triangle lying in the plane goes to the
    // split's side for it; any other is below when it ends at or below the plane, above when it
    // starts at or above it, and both otherwise.
    const auto axis = std::size_t(split.axis);
    const float p = split.pos;
    SmallNode below, above;
    below.box = in.box;
    below.box.max[axis] = p;
    above.box = in.box;
    above.box.min[axis] = p;
    std::array<std::uint8_t, kSmallNode> side{};
    std::uint32_t n_below = 0, n_above = 0, n_both = 0;
    for (std::uint32_t i = 0; i < n; ++i) {
      const float mn = in.min[axis][i], mx = in.max[axis][i];
      std::uint8_t sd;
      if (mn == mx)
        sd = mn < p               ? kBelowOnly
             : mn > p             ? kAboveOnly
             : split.planar_below ? kBelowOnly
                                  : kAboveOnly;
      else
        sd = mx <= p ? kBelowOnly : mn >= p ? kAboveOnly : kBoth;
      side[i] = sd;
      n_below += sd != kAboveOnly;
      n_above += sd != kBelowOnly;
      n_both += sd == kBoth;
    }
    c.sah += double(options_.traversal_cost) * double(area);
    if (n_above == 0 || n_below == 0) {
      // One side empty: the other child has the node's triangles, boxes and all.
      // (The empty child keeps n = 0.)
      SmallNode& full = n_above == 0 ? below : above;
      const Aabb box = full.box;
      full = in;
      full.box = box;
    } else {
      // Straddlers get their parts' boxes in each child (as their new events would hold them);
      // the work counters as split_node counts the same split.
      c.events += 6 * std::uint64_t(n_both) + 2 * events;
      std::array<std::uint32_t, 3> new_below{}, new_above{};
      for (SmallNode* child : {&below, &above}) {
        child->n = 0;
        for (std::size_t a = 0; a < 3; ++a) {
          std::fill(std::begin(child->min[a]), std::end(child->min[a]), kInf);
          std::fill(std::begin(child->max[a]), std::end(child->max[a]), kInf);
        }
      }
      for (std::uint32_t i = 0; i < n; ++i) {
        Aabb parts[2];
        if (side[i] == kBoth)
          straddler_parts(in.tris[i], in.box, split, below.box, above.box, parts);
        for (int k = 0; k < 2; ++k) {
          if (side[i] == (k == 0 ? kAboveOnly : kBelowOnly)) continue;
          SmallNode& child = k == 0 ? below : above;
          const std::uint32_t j = child.n++;
          child.tris[j] = in.tris[i];
          for (std::size_t a = 0; a < 3; ++a) {
            if (side[i] != kBoth) {
              child.min[a][j] = in.min[a][i];
              child.max[a][j] = in.max[a][i];
              continue;
            }
            // Positions as events hold them (-0 made +0).
            child.min[a][j] = parts[k].min[a] + 0.0f;
            child.max[a][j] = parts[k].max[a] + 0.0f;
            (k == 0 ? new_below : new_above)[a] += parts[k].min[a] == parts[k].max[a] ? 1 : 2;
          }
        }
      }
      for (std::size_t a = 0; a < 3; ++a)
        c.sort_work += sort_cost(new_below[a]) + sort_cost(new_above[a]);
    }
    build_small(below, depth + 1, out);
    const std::size_t above_index = out.nodes.size();
    build_small(above, depth + 1, out);
    out.nodes[node].bits = (std::uint32_t(above_index) << 2) | std::uint32_t(split.axis);
    out.nodes[node].split = split.pos;
  }

  const TriangleView& tris_;
  const KdBuildOptions& options_;
  std::uint32_t max_depth_;
  bool simd_; ///< options_.simd on a CPU with AVX2
};

} // namespace

void KdTree::build(const TriangleView& tris, const KdBuildOptions& requested) {
  const auto start = std::chrono::steady_clock::now();
  // On one thread the parallel build's tasks would run one after the other anyway, but each
  // large node's subtree would still go into arrays of its own to be spliced (3-4% of the
  // build): the sequential build appends in the same depth-first order, so the tree is the same.
  KdBuildOptions options = requested;
  if (tbb::this_task_arena::max_concurrency() == 1) options.parallel = false;
  tris_ = tris;
  bounds_ = Aabb{};
  nodes_.clear();
  indices_.clear();
  stats_ = KdBuildStats{};
  if (tris.count >= kMaxTriangles) throw std::length_error("kd-tree: too many triangles");

  // The root: every triangle whose vertices are all finite, with its events.
  Scratch scratch;
  NodeInput root;
  root.tris.allocate(nullptr, tris.count);
  for (std::uint32_t i = 0; i < tris.count; ++i) {
    if (is_finite(tris.vertex(i, 0)) && is_finite(tris.vertex(i, 1)) &&
        is_finite(tris.vertex(i, 2)))
      root.tris.push_back(i);
  }
  stats_.skipped_triangles = tris.count - std::uint32_t(root.tris.size());
  const std::size_t n = root.tris.size();
  if (n == 0) {
    stats_.build_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return;
  }
  for (std::size_t a = 0; a < 3; ++a) root.events[a].allocate(nullptr, 2 * n);
  for (std::uint32_t l = 0; l < n; ++l) {
    const Aabb b = tris.bounds(root.tris[l]);
    bounds_.grow(b);
    push_events(b, l, root.events);
  }
  root.box = bounds_;
  Counters sorting;
  {
    std::array<std::uint64_t, 3> moved{};
    auto sort_axis = [&](std::size_t a) {
      EventList& list = root.events[a];
      const auto tmp = std::make_unique_for_overwrite<Event[]>(list.size());
      moved[a] = radix_sort_root_events(list.data(), list.size(), tmp.get());
    };
    if (options.parallel && n >= kParallelAxes)
      tbb::parallel_invoke([&] { sort_axis(0); }, [&] { sort_axis(1); }, [&] { sort_axis(2); });
    else
      for (std::size_t a = 0; a < 3; ++a) sort_axis(a);
    sorting.sort_work = moved[0] + moved[1] + moved[2];
  }

  std::uint32_t max_depth = options.max_depth;
  if (max_depth == 0) max_depth = std::uint32_t(8.0 + 1.3 * std::log2(double(n)));
  max_depth = std::min(max_depth, kMaxDepthLimit);

  const float root_area = half_area(bounds_.extent());
  Subtree tree;
  tree.counters = sorting;
  Builder(tris, options, max_depth).build(std::move(root), 0, tree, scratch);
  nodes_ = std::move(tree.nodes);
  indices_ = std::move(tree.indices);

  const Counters& c = tree.counters;
  stats_.nodes = std::uint32_t(nodes_.size());
  stats_.leaves = c.leaves;
  stats_.empty_leaves = c.empty_leaves;
  stats_.max_depth = c.max_depth;
  stats_.leaf_references = c.references;
  stats_.sah_cost = root_area > 0.0f ? float(c.sah / double(root_area)) : 0.0f;
  stats_.bytes = nodes_.size() * sizeof(gpu::KdNode) + indices_.size() * sizeof(std::uint32_t);
  stats_.events_processed = c.events;
  stats_.sort_work = c.sort_work;
  stats_.build_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// ---- Single-ray traversal -----------------------------------------------------------------------

namespace {

/// Single rays test a leaf's triangles four at a time from this many on (bench, native section:
/// groups from 2 on cost the small scene's primary rays 5%, from 3 on they gain 5-8% on both).
constexpr std::uint32_t kMinLeafGroup = 3;

/// Up to four triangles of a leaf, ids[0, k), against one ray at once (SSE lanes: triangles):
/// the same result as intersect_closest (AnyHit: intersect_any) on each in turn, to the bit. The
/// lanes compute Woop et al.'s test with the scalar test's operations in its order, against the
/// ray's tfar at the start; the lanes that pass are then taken in order, each against the tfar
/// its predecessors left (the two comparisons that depend on it), as the scalar loop would.
/// A lane whose edge function rounds to 0 sends the group to the scalar test (its double
/// fallback). Returns whether it hit (AnyHit: whether any lies within the interval).
template <bool AnyHit>
bool leaf4_watertight(PreparedRay& r, const TriangleView& tris, const std::uint32_t* ids, int k,
                      TriangleHit* hit) {
  alignas(16) float g[9][4]; // vertex v, ray-frame component c: g[3 * v + c][lane]
  for (int j = 0; j < 4; ++j) {
    const uvec3 tri = tris.triangles[ids[j < k ? j : 0]];
    for (int v = 0; v < 3; ++v) {
      const vec3& p = tris.positions[tri[v]];
      g[3 * v + 0][j] = p[r.kx] - r.org[r.kx];
      g[3 * v + 1][j] = p[r.ky] - r.org[r.ky];
      g[3 * v + 2][j] = p[r.kz] - r.org[r.kz];
    }
  }
  const __m128 sx = _mm_set1_ps(r.sx), sy = _mm_set1_ps(r.sy), sz = _mm_set1_ps(r.sz);
  const __m128 az0 = _mm_load_ps(g[2]), bz0 = _mm_load_ps(g[5]), cz0 = _mm_load_ps(g[8]);
  const __m128 ax = _mm_sub_ps(_mm_load_ps(g[0]), _mm_mul_ps(sx, az0));
  const __m128 ay = _mm_sub_ps(_mm_load_ps(g[1]), _mm_mul_ps(sy, az0));
  const __m128 bx = _mm_sub_ps(_mm_load_ps(g[3]), _mm_mul_ps(sx, bz0));
  const __m128 by = _mm_sub_ps(_mm_load_ps(g[4]), _mm_mul_ps(sy, bz0));
  const __m128 cx = _mm_sub_ps(_mm_load_ps(g[6]), _mm_mul_ps(sx, cz0));
  const __m128 cy = _mm_sub_ps(_mm_load_ps(g[7]), _mm_mul_ps(sy, cz0));
  const __m128 U = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
  const __m128 V = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
  const __m128 W = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
  const __m128 zero = _mm_setzero_ps();
  const unsigned lanes = (1u << k) - 1u;
  const unsigned zero_edge =
      unsigned(_mm_movemask_ps(_mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(U, zero), _mm_cmpeq_ps(V, zero)),
                                         _mm_cmpeq_ps(W, zero)))) &
      lanes;
  if (zero_edge != 0) [[unlikely]] {
    bool found = false;
    for (int j = 0; j < k; ++j) {
      if constexpr (AnyHit) {
        if (intersect_any<TriangleTest::watertight>(r, tris, ids[j])) return true;
      } else {
        found |= intersect_closest<TriangleTest::watertight>(r, tris, ids[j], *hit);
      }
    }
    return found;
  }
  const __m128 negative =
      _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(U, zero), _mm_cmplt_ps(V, zero)), _mm_cmplt_ps(W, zero));
  const __m128 positive =
      _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(U, zero), _mm_cmpgt_ps(V, zero)), _mm_cmpgt_ps(W, zero));
  unsigned pass = unsigned(_mm_movemask_ps(_mm_andnot_ps(_mm_and_ps(negative, positive),
                                                         _mm_castsi128_ps(_mm_set1_epi32(-1))))) &
                  lanes;
  if (pass == 0) return false;
  const __m128 det = _mm_add_ps(_mm_add_ps(U, V), W);
  pass &= ~unsigned(_mm_movemask_ps(_mm_cmpeq_ps(det, zero)));
  if (pass == 0) return false;
  const __m128 az = _mm_mul_ps(sz, az0), bz = _mm_mul_ps(sz, bz0), cz = _mm_mul_ps(sz, cz0);
  const __m128 T = _mm_add_ps(_mm_add_ps(_mm_mul_ps(U, az), _mm_mul_ps(V, bz)), _mm_mul_ps(W, cz));
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 abs_det = _mm_andnot_ps(sign, det);
  const __m128 signed_t = _mm_xor_ps(T, _mm_and_ps(det, sign));
  const __m128 tnear = _mm_set1_ps(r.tnear), tmax = _mm_set1_ps(r.tfar);
  pass &= unsigned(_mm_movemask_ps(_mm_and_ps(_mm_cmpgt_ps(signed_t, _mm_mul_ps(tnear, abs_det)),
                                              _mm_cmplt_ps(signed_t, _mm_mul_ps(tmax, abs_det)))));
  if (pass == 0) return false;
  const __m128 inv_det = _mm_div_ps(_mm_set1_ps(1.0f), det);
  const __m128 t = _mm_mul_ps(T, inv_det);
  pass &= unsigned(_mm_movemask_ps(_mm_and_ps(_mm_cmpgt_ps(t, tnear), _mm_cmplt_ps(t, tmax))));
  if (pass == 0) return false;
  if constexpr (AnyHit) {
    return true;
  } else {
    alignas(16) float lane_t[4], lane_st[4], lane_ad[4], lane_u[4], lane_v[4];
    _mm_store_ps(lane_t, t);
    _mm_store_ps(lane_st, signed_t);
    _mm_store_ps(lane_ad, abs_det);
    _mm_store_ps(lane_u, _mm_mul_ps(V, inv_det));
    _mm_store_ps(lane_v, _mm_mul_ps(W, inv_det));
    bool found = false;
    for (; pass != 0; pass &= pass - 1) {
      const int j = std::countr_zero(pass);
      // Against the tfar the lanes before it left, as the scalar loop tests it.
      if (!(lane_st[j] < r.tfar * lane_ad[j]) || !(lane_t[j] < r.tfar)) continue;
      r.tfar = lane_t[j];
      hit->t = lane_t[j];
      hit->u = lane_u[j];
      hit->v = lane_v[j];
      hit->prim = ids[j];
      found = true;
    }
    return found;
  }
}

} // namespace

template <TriangleTest Test, bool AnyHit>
bool KdTree::traverse(PreparedRay& r, TriangleHit* hit) const {
  if (nodes_.empty() || !r.valid()) return false;
  float tmin, tmax;
  if (!intersect_box(r, bounds_.min, bounds_.max, tmin, tmax)) return false;

  struct Entry {
    std::uint32_t node;
    float tmin, tmax;
  };
  Entry stack[kStackSize];
  int sp = 0;
  std::uint32_t node = 0;
  bool found = false;
  const gpu::KdNode* nodes = nodes_.data();
  for (;;) {
    const gpu::KdNode n = nodes[node];
    const std::uint32_t axis = n.bits & 3u;
    if (axis != gpu::kKdLeaf) {
      const float t_split = (n.split - r.org[int(axis)]) * r.inv_dir[int(axis)];
      // The near child is the one the direction comes from. A plane at or behind the origin
      // leaves only the far child (the origin is past it, or on it and moving away); one beyond
      // the interval only the near child. -0 and +0 directions give ∓inf here and fall in the
      // right case; a ray lying in the plane, parallel to it (NaN), visits both over its whole
      // interval.
      const std::uint32_t above = n.bits >> 2;
      const std::uint32_t near = r.neg[axis] != 0 ? above : node + 1;
      const std::uint32_t far = r.neg[axis] != 0 ? node + 1 : above;
      if (t_split > tmax * kUp) {
        node = near;
      } else if (t_split <= 0.0f || t_split < tmin * kDown) {
        node = far;
      } else if (std::isnan(t_split)) [[unlikely]] {
        stack[sp++] = {far, tmin, tmax};
        node = near;
      } else {
        stack[sp++] = {far, t_split, tmax};
        node = near;
        tmax = t_split;
      }
      continue;
    }

    const std::uint32_t count = n.bits >> 2;
    const std::uint32_t* ids = indices_.data() + n.first;
    std::uint32_t k = 0;
    if constexpr (Test == TriangleTest::watertight) {
      // Groups of up to four; one or two left over go to the scalar test, which is faster for
      // them (gathering the lanes costs about what two early-out scalar tests do).
      while (k + kMinLeafGroup <= count) {
        const std::uint32_t group = std::min<std::uint32_t>(4, count - k);
        if (leaf4_watertight<AnyHit>(r, tris_, ids + k, int(group), hit)) {
          if constexpr (AnyHit) return true;
          found = true;
        }
        k += group;
      }
    }
    for (; k < count; ++k) {
      if constexpr (AnyHit) {
        if (intersect_any<Test>(r, tris_, ids[k])) return true;
      } else {
        if (intersect_closest<Test>(r, tris_, ids[k], *hit)) found = true;
      }
    }
    // The nearest pending cell that the ray (shortened by its hits) still reaches. A hit found
    // here beyond the cell's exit is kept, but does not end the traversal: with perfect splits a
    // closer triangle may lie in a later cell. Each entry is culled on its own entry distance
    // rather than stopping at the first one beyond the hit: a ray lying in a split plane visits
    // both children over the same interval, and then the stack is not sorted by distance.
    for (;;) {
      if (sp == 0) return found;
      const Entry& e = stack[--sp];
      if (r.tfar < e.tmin * kDown) continue;
      node = e.node;
      tmin = e.tmin;
      tmax = e.tmax;
      break;
    }
  }
}

bool KdTree::intersect(PreparedRay& r, TriangleHit& hit, TriangleTest test) const {
  if (test == TriangleTest::watertight) return traverse<TriangleTest::watertight, false>(r, &hit);
  return traverse<TriangleTest::moller_trumbore, false>(r, &hit);
}

bool KdTree::occluded(const PreparedRay& r, TriangleTest test) const {
  PreparedRay copy = r;
  if (test == TriangleTest::watertight)
    return traverse<TriangleTest::watertight, true>(copy, nullptr);
  return traverse<TriangleTest::moller_trumbore, true>(copy, nullptr);
}

// ---- Packet traversal ---------------------------------------------------------------------------

namespace {

/// What the packet kernels read of a tree.
struct KdView {
  const gpu::KdNode* nodes;
  const std::uint32_t* indices;
  const TriangleView* tris;
};

} // namespace

// The packet kernel is written once (kdtree_packet.inl) over the vector operations of
// simd_lanes.h and compiled twice: for SSE (baseline x86-64) and, in functions with the avx2 target
// attribute, for AVX2, chosen at run time.
namespace sse {
namespace {
using namespace simd_sse;
#define SPECULA_SIMD_TARGET
#include "kdtree_packet.inl"
#undef SPECULA_SIMD_TARGET
} // namespace
} // namespace sse

namespace avx2 {
namespace {
using namespace simd_avx2;
#define SPECULA_SIMD_TARGET __attribute__((target("avx2")))
#include "kdtree_packet.inl"
#undef SPECULA_SIMD_TARGET
} // namespace
} // namespace avx2

template <int N, TriangleTest Test, bool AnyHit>
unsigned KdTree::walk_packet(const RayPacket<N>& rays, const bool* active, PreparedRay* prepared,
                             TriangleHit* lane_hits) const {
  if (nodes_.empty()) return 0;
  alignas(32) float tmin[N];
  alignas(32) float tmax[N];
  unsigned mask = 0;
  std::uint32_t neg[3] = {0, 0, 0};
  // Lanes that agree on their signs and ray space are prepared in vector steps; others one by one
  // (the same bits either way).
  WatertightLanesOf<N> lanes;
  const bool vector_prepared =
      prepare_coherent_lanes<N>(rays, active, &bounds_, prepared, tmin, tmax, mask, neg, lanes);
  if (!vector_prepared) {
    for (int i = 0; i < N; ++i) {
      tmin[i] = 0.0f;
      tmax[i] = -1.0f;
      if (!active[i]) continue;
      prepared[i] =
          PreparedRay::make(vec3(rays.ox[i], rays.oy[i], rays.oz[i]),
                            vec3(rays.dx[i], rays.dy[i], rays.dz[i]), rays.tnear[i], rays.tfar[i]);
      if (!prepared[i].valid()) continue;
      if (!intersect_box(prepared[i], bounds_.min, bounds_.max, tmin[i], tmax[i])) continue;
      mask |= 1u << i;
    }
  }
  if (mask == 0) return 0;

  // One direction sign per axis over the live lanes, or each lane on its own.
  // Two lanes or more (not std::popcount: without POPCNT in the baseline ISA it is a library
  // call).
  bool coherent = (mask & (mask - 1)) != 0;
  if (!vector_prepared) {
    const int lead = std::countr_zero(mask);
    for (int a = 0; a < 3 && coherent; ++a) {
      neg[a] = prepared[lead].neg[a];
      for (unsigned m = mask; m; m &= m - 1)
        coherent = coherent && prepared[std::countr_zero(m)].neg[a] == neg[a];
    }
  }

  unsigned found = 0;
  if (coherent) {
    const KdView view{nodes_.data(), indices_.data(), &tris_};
    // The SIMD triangle test needs one ray space for all lanes (camera packets have it).
    bool shared_axes = vector_prepared;
    if constexpr (N == 8) {
      if (!vector_prepared) shared_axes = simd_avx2::make_watertight_lanes(prepared, mask, lanes);
      found = avx2::traverse_packet<Test, AnyHit>(view, prepared, lane_hits, tmin, tmax, mask, neg,
                                                  lanes, shared_axes);
    } else {
      if (!vector_prepared) shared_axes = simd_sse::make_watertight_lanes(prepared, mask, lanes);
      found = sse::traverse_packet<Test, AnyHit>(view, prepared, lane_hits, tmin, tmax, mask, neg,
                                                 lanes, shared_axes);
    }
    if constexpr (!AnyHit) {
      found = 0;
      for (unsigned m = mask; m; m &= m - 1)
        if (lane_hits[std::countr_zero(m)].hit()) found |= 1u << std::countr_zero(m);
    }
  } else {
    for (unsigned m = mask; m; m &= m - 1) {
      const int i = std::countr_zero(m);
      if (traverse<Test, AnyHit>(prepared[i], AnyHit ? nullptr : &lane_hits[i])) found |= 1u << i;
    }
  }
  return found;
}

template <int N, TriangleTest Test>
void KdTree::intersect_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active,
                              TestTag<Test>) const {
  PreparedRay prepared[N];
  TriangleHit lane_hits[N];
  for (unsigned m = walk_packet<N, Test, false>(rays, active, prepared, lane_hits); m; m &= m - 1) {
    const int i = std::countr_zero(m);
    rays.tfar[i] = prepared[i].tfar;
    hits.set(i, lane_hits[i]);
  }
}

template <int N, TriangleTest Test>
unsigned KdTree::occluded_packet(const RayPacket<N>& rays, const bool* active,
                                 TestTag<Test>) const {
  PreparedRay prepared[N];
  TriangleHit lane_hits[N];
  return walk_packet<N, Test, true>(rays, active, prepared, lane_hits);
}

unsigned KdTree::occluded4(const RayPacket<4>& rays, const bool active[4],
                           TriangleTest test) const {
  return run_occlusion_packet(rays, active, test,
                              [this](auto&&... a) { return occluded_packet(a...); });
}

unsigned KdTree::occluded8(const RayPacket<8>& rays, const bool active[8],
                           TriangleTest test) const {
  return run_occlusion_packet(rays, active, test,
                              [this](auto&&... a) { return occluded_packet(a...); });
}

void KdTree::intersect4(RayPacket<4>& rays, PacketHits<4>& hits, const bool active[4],
                        TriangleTest test) const {
  run_packet(rays, hits, active, test, [this](auto&&... a) { intersect_packet(a...); });
}

void KdTree::intersect8(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                        TriangleTest test) const {
  run_packet(rays, hits, active, test, [this](auto&&... a) { intersect_packet(a...); });
}

} // namespace specula::accel
