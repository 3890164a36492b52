// Shading points of many hits at once (shading_batch.h): shading_point's operations for a baked
// instance, in their order, eight hits at a time with AVX2; the hits the vector code does not
// take, one at a time.

#include "specula/trace/shading_batch.h"

#include "specula/core/assert.h"
#include "specula/trace/lanes_avx2.h"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>

namespace specula::detail {
namespace {

static_assert(std::is_standard_layout_v<Hit> && sizeof(Hit) == 8 * sizeof(float) &&
                  std::is_standard_layout_v<gpu::GpuInstance> &&
                  std::is_standard_layout_v<gpu::GpuMesh> &&
                  sizeof(gpu::GpuInstance) % sizeof(float) == 0 &&
                  sizeof(gpu::GpuMesh) % sizeof(float) == 0 && sizeof(uvec3) == 12 &&
                  sizeof(vec3) == 12,
              "the vector code gathers these structures' fields as 32-bit words");

constexpr int word(std::size_t bytes) { return int(bytes / sizeof(float)); }

using namespace avx2;

/// ShadingPoint as 16 words, in member order: position, spawn point, spawn error, geometric and
/// shading normals (15 floats), then front_face in the low byte of the last word (1 or 0, the
/// padding bytes 0).
static_assert(sizeof(ShadingPoint) == 16 * sizeof(float) &&
              offsetof(ShadingPoint, spawn_point) == 3 * sizeof(float) &&
              offsetof(ShadingPoint, spawn_error) == 6 * sizeof(float) &&
              offsetof(ShadingPoint, geometric_normal) == 9 * sizeof(float) &&
              offsetof(ShadingPoint, shading_normal) == 12 * sizeof(float) &&
              offsetof(ShadingPoint, front_face) == 15 * sizeof(float) &&
              std::is_trivially_copyable_v<ShadingPoint>);

/// Hits i0 … i0 + 7; returns the mask of the lanes it wrote (the rest are the caller's).
SPECULA_AVX2 unsigned eight_points(const SceneTables& tables, const Hit* hits,
                                   const Directions& dirs, ShadingPoint* out) {
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i all = _mm256_set1_epi32(-1);
  const __m256i hit_words = _mm256_slli_epi32(lane, 3); // 8 words a Hit
  const auto* h = reinterpret_cast<const std::uint32_t*>(hits);
  const __m256i instance = gather_i(h + word(offsetof(Hit, instance)), hit_words, all);
  const __m256i active =
      _mm256_andnot_si256(_mm256_cmpeq_epi32(instance, _mm256_set1_epi32(int(kNoInstance))), all);
  if (_mm256_testz_si256(active, active) != 0) return 0;
  const __m256i primitive = gather_i(h + word(offsetof(Hit, primitive)), hit_words, active);
  const auto* hf = reinterpret_cast<const float*>(hits);
  const __m256 u = gather_f(hf + word(offsetof(Hit, uv)), hit_words, active);
  const __m256 v = gather_f(hf + word(offsetof(Hit, uv)) + 1, hit_words, active);
  const V3 object_normal{gather_f(hf + word(offsetof(Hit, object_normal)), hit_words, active),
                         gather_f(hf + word(offsetof(Hit, object_normal)) + 1, hit_words, active),
                         gather_f(hf + word(offsetof(Hit, object_normal)) + 2, hit_words, active)};
  const __m256i dir_words = _mm256_mullo_epi32(lane, _mm256_set1_epi32(int(dirs.stride)));
  const V3 direction{gather_f(dirs.x, dir_words, active), gather_f(dirs.y, dir_words, active),
                     gather_f(dirs.z, dir_words, active)};

  // The instance's flags and mesh, the mesh's ranges.
  const __m256i inst_words =
      _mm256_mullo_epi32(instance, _mm256_set1_epi32(word(sizeof(gpu::GpuInstance))));
  const auto* inst = reinterpret_cast<const std::uint32_t*>(tables.instances.data());
  const __m256i flags =
      gather_i(inst + word(offsetof(gpu::GpuInstance, flags)), inst_words, active);
  const __m256i identity =
      _mm256_cmpeq_epi32(_mm256_and_si256(flags, _mm256_set1_epi32(int(gpu::kInstanceIdentity))),
                         _mm256_set1_epi32(int(gpu::kInstanceIdentity)));
  const __m256i mesh = gather_i(inst + word(offsetof(gpu::GpuInstance, mesh)), inst_words, active);
  const __m256i mesh_words =
      _mm256_mullo_epi32(mesh, _mm256_set1_epi32(word(sizeof(gpu::GpuMesh))));
  const auto* meshes = reinterpret_cast<const std::uint32_t*>(tables.meshes.data());
  const __m256i first_vertex =
      gather_i(meshes + word(offsetof(gpu::GpuMesh, first_vertex)), mesh_words, active);
  const __m256i first_triangle =
      gather_i(meshes + word(offsetof(gpu::GpuMesh, first_triangle)), mesh_words, active);
  const __m256i first_normal =
      gather_i(meshes + word(offsetof(gpu::GpuMesh, first_normal)), mesh_words, active);
  const __m256i tri3 =
      _mm256_mullo_epi32(_mm256_add_epi32(first_triangle, primitive), _mm256_set1_epi32(3));
  const auto* tris = reinterpret_cast<const std::uint32_t*>(tables.triangles.data());
  const __m256i t0 = gather_i(tris, tri3, active);
  const __m256i t1 = gather_i(tris + 1, tri3, active);
  const __m256i t2 = gather_i(tris + 2, tri3, active);
  const V3 p0 = gather3(tables.positions.data(), _mm256_add_epi32(first_vertex, t0), active);
  const V3 p1 = gather3(tables.positions.data(), _mm256_add_epi32(first_vertex, t1), active);
  const V3 p2 = gather3(tables.positions.data(), _mm256_add_epi32(first_vertex, t2), active);

  // shading_point: the hit from its barycentrics (a baked instance's object space is the world).
  const __m256 one = _mm256_set1_ps(1.0f);
  const __m256 zero = _mm256_setzero_ps();
  const __m256 w = sub(sub(one, u), v);
  const V3 position = interpolate(w, u, v, p0, p1, p2);
  // spawn_point: the hit's error bound (error_at of barycentric_error) ...
  const V3 largest = max(abs(p0), max(abs(p1), abs(p2)));
  const __m256 magnitude = max(largest.x, max(largest.y, largest.z));
  const __m256 g7 = _mm256_set1_ps(gamma_bound(7));
  const __m256 g8m = mul(_mm256_set1_ps(gamma_bound(8)), magnitude);
  const V3 sum = add(add(abs(scale(w, p0)), abs(scale(u, p1))), abs(scale(v, p2)));
  const V3 bary{add(mul(g7, sum.x), g8m), add(mul(g7, sum.y), g8m), add(mul(g7, sum.z), g8m)};
  const __m256 g31 = _mm256_set1_ps(gamma_bound(3) + 1.0f);
  const __m256 g3 = _mm256_set1_ps(gamma_bound(3));
  const V3 abs_position = abs(position);
  const V3 error{add(mul(g31, bary.x), mul(g3, abs_position.x)),
                 add(mul(g31, bary.y), mul(g3, abs_position.y)),
                 add(mul(g31, bary.z), mul(g3, abs_position.z))};
  // ... and inset_barycentrics' fast test: barycentrics inside the triangle as they are, and
  // every one far enough from its edge.
  const __m256 margin = mul(_mm256_set1_ps(kEdgeInset), _mm256_sqrt_ps(dot(error, error)));
  const V3 e0 = sub(p2, p1), e1 = sub(p0, p2), e2 = sub(p1, p0);
  const V3 c = cross(e2, sub(p2, p0));
  const __m256 c2 = dot(c, c);
  const __m256 m2 = mul(margin, margin);
  __m256 ok = _mm256_and_ps(_mm256_cmp_ps(u, zero, _CMP_GE_OQ), _mm256_cmp_ps(u, one, _CMP_LE_OQ));
  ok = _mm256_and_ps(
      ok, _mm256_and_ps(_mm256_cmp_ps(v, zero, _CMP_GE_OQ), _mm256_cmp_ps(v, one, _CMP_LE_OQ)));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(add(u, v), one, _CMP_LE_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(w, zero, _CMP_GE_OQ)); // max(0, w) is w
  ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(c2, _mm256_set1_ps(1e-30f), _CMP_GT_OQ),
                                       _mm256_cmp_ps(c2, _mm256_set1_ps(1e30f), _CMP_LT_OQ)));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(mul(mul(w, w), c2), mul(m2, dot(e0, e0)), _CMP_GE_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(mul(mul(u, u), c2), mul(m2, dot(e1, e1)), _CMP_GE_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(mul(mul(v, v), c2), mul(m2, dot(e2, e2)), _CMP_GE_OQ));
  ok = _mm256_and_ps(ok, _mm256_castsi256_ps(_mm256_and_si256(active, identity)));
  const unsigned taken = unsigned(_mm256_movemask_ps(ok));
  if (taken == 0) return 0;

  // The normals: the geometric one facing the ray, the interpolated one on its side.
  const V3 normal =
      scale(_mm256_div_ps(one, _mm256_sqrt_ps(dot(object_normal, object_normal))), object_normal);
  const __m256 front = _mm256_cmp_ps(dot(normal, direction), zero, _CMP_LT_OQ);
  const V3 geometric{_mm256_blendv_ps(neg(normal.x), normal.x, front),
                     _mm256_blendv_ps(neg(normal.y), normal.y, front),
                     _mm256_blendv_ps(neg(normal.z), normal.z, front)};
  V3 shading = geometric;
  const __m256i smooth = _mm256_and_si256(
      _mm256_and_si256(
          _mm256_castps_si256(ok),
          _mm256_cmpeq_epi32(_mm256_and_si256(flags, _mm256_set1_epi32(int(gpu::kInstanceSmooth))),
                             _mm256_set1_epi32(int(gpu::kInstanceSmooth)))),
      _mm256_andnot_si256(_mm256_cmpeq_epi32(first_normal, _mm256_set1_epi32(int(gpu::kNoIndex))),
                          all));
  if (_mm256_testz_si256(smooth, smooth) == 0) {
    const V3 n0 = gather3(tables.normals.data(), _mm256_add_epi32(first_normal, t0), smooth);
    const V3 n1 = gather3(tables.normals.data(), _mm256_add_epi32(first_normal, t1), smooth);
    const V3 n2 = gather3(tables.normals.data(), _mm256_add_epi32(first_normal, t2), smooth);
    const V3 ns = interpolate(w, u, v, n0, n1, n2);
    const __m256 len = _mm256_sqrt_ps(dot(ns, ns));
    const __m256 usable = _mm256_and_ps(
        _mm256_and_ps(_mm256_castsi256_ps(smooth), _mm256_cmp_ps(len, zero, _CMP_GT_OQ)),
        _mm256_cmp_ps(len, _mm256_set1_ps(std::numeric_limits<float>::infinity()), _CMP_LT_OQ));
    const V3 unit{_mm256_div_ps(ns.x, len), _mm256_div_ps(ns.y, len), _mm256_div_ps(ns.z, len)};
    const __m256 flip = _mm256_cmp_ps(dot(unit, geometric), zero, _CMP_LT_OQ);
    const V3 facing{_mm256_blendv_ps(unit.x, neg(unit.x), flip),
                    _mm256_blendv_ps(unit.y, neg(unit.y), flip),
                    _mm256_blendv_ps(unit.z, neg(unit.z), flip)};
    shading = {_mm256_blendv_ps(shading.x, facing.x, usable),
               _mm256_blendv_ps(shading.y, facing.y, usable),
               _mm256_blendv_ps(shading.z, facing.z, usable)};
  }

  // Each lane's ShadingPoint is 16 words (the layout asserted above; the spawn point is the
  // position, no inset needed): two 8 × 8 transposes of the columns give them lane by lane, two
  // stores each for the lanes taken (a column at a time through memory had the compiler copy
  // them all on the stack first).
  const __m256 front_word =
      _mm256_castsi256_ps(_mm256_and_si256(_mm256_castps_si256(front), _mm256_set1_epi32(1)));
  __m256 low[8] = {position.x, position.y, position.z, position.x,
                   position.y, position.z, error.x,    error.y};
  __m256 high[8] = {error.z,   geometric.x, geometric.y, geometric.z,
                    shading.x, shading.y,   shading.z,   front_word};
  transpose8(low);
  transpose8(high);
  for (unsigned l = 0; l < 8; ++l) {
    if ((taken >> l & 1u) == 0) continue;
    float* words = reinterpret_cast<float*>(out + l);
    _mm256_storeu_ps(words, low[l]);
    _mm256_storeu_ps(words + 8, high[l]);
  }
  return taken;
}

} // namespace

bool shading_points_vectorised() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

std::size_t shading_points(const SceneTables& tables, std::span<const Hit> hits,
                           const Directions& directions, std::span<ShadingPoint> out, bool simd) {
  SPECULA_ASSERT(out.size() >= hits.size());
  // The gathers index words with 32-bit offsets.
  constexpr std::size_t kMostWords = std::size_t(std::numeric_limits<std::int32_t>::max());
  const bool vector = simd && shading_points_vectorised() && directions.stride <= kMostWords / 8 &&
                      tables.positions.size() <= kMostWords / 3 &&
                      tables.normals.size() <= kMostWords / 3 &&
                      tables.triangles.size() <= kMostWords / 3 &&
                      tables.instances.size() <= kMostWords / sizeof(gpu::GpuInstance) &&
                      tables.meshes.size() <= kMostWords / sizeof(gpu::GpuMesh);
  std::size_t i = 0, vectorised = 0;
  if (vector) {
    for (; i + 8 <= hits.size(); i += 8) {
      const std::size_t offset = i * directions.stride;
      const Directions eight{directions.x + offset, directions.y + offset, directions.z + offset,
                             directions.stride};
      const unsigned taken = eight_points(tables, hits.data() + i, eight, out.data() + i);
      // The lanes taken, counted without std::popcount (a library call without POPCNT in the
      // baseline ISA, once per eight hits here).
      unsigned lanes = taken - ((taken >> 1) & 0x55u);
      lanes = (lanes & 0x33u) + ((lanes >> 2) & 0x33u);
      vectorised += std::size_t((lanes + (lanes >> 4)) & 0x0Fu);
      for (std::size_t l = 0; l < 8; ++l)
        if ((taken >> l & 1u) == 0 && hits[i + l].hit())
          out[i + l] = shading_point(tables, hits[i + l], directions[i + l]);
    }
  }
  for (; i < hits.size(); ++i)
    if (hits[i].hit()) out[i] = shading_point(tables, hits[i], directions[i]);
  return vectorised;
}

} // namespace specula::detail
