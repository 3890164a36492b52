// What a wave's path vertices start from (vertex_starts.h): offset_ray_origin and
// sample_area_light, one vertex at a time, or eight at a time with AVX2 repeating their operations
// in their order (tests/trace/test_vertex_starts.cpp compares the two bit for bit).

#include "specula/trace/vertex_starts.h"

#include "specula/core/assert.h"
#include "specula/geometry/ray_offset.h"
#include "specula/trace/area_lights.h"
#include "specula/trace/lanes_avx2.h"

#include <cstddef>
#include <limits>
#include <type_traits>

namespace specula::detail {

void VertexStarts::resize(std::size_t n) {
  for (std::vector<float>* v : {&ox, &oy, &oz, &lx, &ly, &lz, &distance, &pdf, &er, &eg, &eb})
    v->resize(n);
}

namespace {

using namespace avx2;

/// Vertex k, one at a time.
void one_vertex(const VertexInputs& in, std::size_t k, VertexStarts& out) {
  const std::size_t i = k / in.per_point;
  if (!in.hits[i].hit()) return;
  const ShadingPoint& sp = in.points[i];
  const vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
  out.ox[k] = origin.x;
  out.oy[k] = origin.y;
  out.oz[k] = origin.z;
  if (in.emitters == nullptr) return;
  const float* u = in.light_u + k * in.stride;
  const AreaLightSample ls = sample_area_light(*in.emitters, sp.position, u[0], u[1], u[2]);
  out.lx[k] = ls.to_light.x;
  out.ly[k] = ls.to_light.y;
  out.lz[k] = ls.to_light.z;
  out.distance[k] = ls.distance;
  out.pdf[k] = ls.pdf;
  out.er[k] = ls.emission.x;
  out.eg[k] = ls.emission.y;
  out.eb[k] = ls.emission.z;
}

/// next_float_up, lane by lane: NaN and +inf stay, both zeros give the smallest denormal, the
/// bits step away from zero above it and towards it below.
SPECULA_AVX2 inline __m256 next_float_up8(__m256 x) {
  const __m256i bits = _mm256_castps_si256(x);
  const __m256 zero = _mm256_setzero_ps();
  const __m256i one = _mm256_set1_epi32(1);
  const __m256i stepped =
      _mm256_blendv_epi8(_mm256_sub_epi32(bits, one), _mm256_add_epi32(bits, one),
                         _mm256_castps_si256(_mm256_cmp_ps(x, zero, _CMP_GT_OQ)));
  __m256i r =
      _mm256_blendv_epi8(stepped, one, _mm256_castps_si256(_mm256_cmp_ps(x, zero, _CMP_EQ_OQ)));
  const __m256 stays = _mm256_or_ps(
      _mm256_cmp_ps(x, x, _CMP_UNORD_Q),
      _mm256_cmp_ps(x, _mm256_set1_ps(std::numeric_limits<float>::infinity()), _CMP_EQ_OQ));
  r = _mm256_blendv_epi8(r, bits, _mm256_castps_si256(stays));
  return _mm256_castsi256_ps(r);
}

/// offset_ray_origin's rounding of one coordinate by the normal's sign.
SPECULA_AVX2 inline __m256 round_away(__m256 po, __m256 n) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 up = next_float_up8(po);
  const __m256 down = neg(next_float_up8(neg(po))); // next_float_down
  const __m256 moved = _mm256_blendv_ps(po, up, _mm256_cmp_ps(n, zero, _CMP_GT_OQ));
  return _mm256_blendv_ps(moved, down, _mm256_cmp_ps(n, zero, _CMP_LT_OQ));
}

/// Vertices k0 … k0 + 7.
template <typename Table>
SPECULA_AVX2 void eight_vertices(const VertexInputs& in, const Table* table, std::size_t k0,
                                 VertexStarts& out) {
  // The shading points' first 12 words (position, spawn point, spawn error, geometric normal),
  // lane by lane, transposed into columns.
  static_assert(sizeof(ShadingPoint) == 16 * sizeof(float) &&
                offsetof(ShadingPoint, position) == 0 &&
                offsetof(ShadingPoint, spawn_point) == 3 * sizeof(float) &&
                offsetof(ShadingPoint, spawn_error) == 6 * sizeof(float) &&
                offsetof(ShadingPoint, geometric_normal) == 9 * sizeof(float) &&
                std::is_trivially_copyable_v<ShadingPoint>);
  __m256 low[8], high[8];
  for (std::size_t l = 0; l < 8; ++l) {
    const auto* words = reinterpret_cast<const float*>(&in.points[(k0 + l) / in.per_point]);
    low[l] = _mm256_loadu_ps(words);
    high[l] = _mm256_loadu_ps(words + 8);
  }
  transpose8(low);
  transpose8(high);
  const V3 position{low[0], low[1], low[2]};
  const V3 spawn{low[3], low[4], low[5]};
  const V3 error{low[6], low[7], high[0]};
  const V3 n{high[1], high[2], high[3]};

  // offset_ray_origin.
  const V3 po = add(spawn, scale(dot(abs(n), error), n));
  _mm256_storeu_ps(out.ox.data() + k0, round_away(po.x, n.x));
  _mm256_storeu_ps(out.oy.data() + k0, round_away(po.y, n.y));
  _mm256_storeu_ps(out.oz.data() + k0, round_away(po.z, n.z));
  if (table == nullptr) return;

  // sample_area_light: EmitterTable::pick's triangle (lanes at or above every cdf take the
  // scalar code's fallback), then sample_emitter_triangle.
  const __m256i at = _mm256_mullo_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                                        _mm256_set1_epi32(int(in.stride)));
  const float* u = in.light_u + k0 * in.stride;
  const __m256 u_pick = _mm256_i32gather_ps(u, at, 4);
  __m256i past;
  const __m256i k = table->pick(u_pick, past);
  if (_mm256_movemask_epi8(past) != 0) {
    for (std::size_t v = k0; v < k0 + 8; ++v) one_vertex(in, v, out);
    return;
  }
  const EmitterSample8 ls = emitter_sample8(*table, k, position, _mm256_i32gather_ps(u + 1, at, 4),
                                            _mm256_i32gather_ps(u + 2, at, 4));
  // The scalar code's values where it gives up: no direction, distance or density.
  const __m256 zero = _mm256_setzero_ps();
  const __m256 placed = _mm256_and_ps(
      _mm256_cmp_ps(ls.distance, zero, _CMP_GT_OQ),
      _mm256_cmp_ps(ls.distance, _mm256_set1_ps(std::numeric_limits<float>::infinity()),
                    _CMP_LT_OQ));
  _mm256_storeu_ps(out.lx.data() + k0, _mm256_and_ps(placed, ls.to_light.x));
  _mm256_storeu_ps(out.ly.data() + k0, _mm256_and_ps(placed, ls.to_light.y));
  _mm256_storeu_ps(out.lz.data() + k0, _mm256_and_ps(placed, ls.to_light.z));
  _mm256_storeu_ps(out.distance.data() + k0, _mm256_and_ps(placed, ls.distance));
  _mm256_storeu_ps(out.pdf.data() + k0, _mm256_and_ps(ls.ok, ls.pdf));
  const V3 emission = field3(*table, k, offsetof(EmitterTriangle, emission));
  _mm256_storeu_ps(out.er.data() + k0, emission.x);
  _mm256_storeu_ps(out.eg.data() + k0, emission.y);
  _mm256_storeu_ps(out.eb.data() + k0, emission.z);
}

template <typename Table>
SPECULA_AVX2 std::size_t eight_at_a_time(const VertexInputs& in, const Table* table,
                                         VertexStarts& out) {
  std::size_t k = 0;
  for (; k + 8 <= in.count; k += 8) eight_vertices(in, table, k, out);
  return k;
}

/// The groups of eight; returns the first vertex left to the scalar code.
SPECULA_AVX2 std::size_t eight_at_a_time(const VertexInputs& in, VertexStarts& out) {
  if (in.emitters == nullptr) return eight_at_a_time<TableInMemory>(in, nullptr, out);
  const std::vector<EmitterTriangle>& triangles = in.emitters->triangles();
  if (triangles.size() <= TableInRegisters::kMost) {
    const TableInRegisters table(triangles);
    return eight_at_a_time(in, &table, out);
  }
  const TableInMemory table(triangles);
  return eight_at_a_time(in, &table, out);
}

} // namespace

bool vertex_starts_vectorised() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

void vertex_starts(const VertexInputs& in, VertexStarts& out, bool simd) {
  SPECULA_ASSERT(in.per_point > 0 && in.count <= in.points.size() * in.per_point &&
                 in.hits.size() == in.points.size());
  out.resize(in.count);
  VertexInputs inputs = in;
  if (inputs.emitters != nullptr && inputs.emitters->empty()) inputs.emitters = nullptr;
  std::size_t k = 0;
  // The gathers index the samples and the triangles' floats with 32-bit offsets.
  if (simd && vertex_starts_vectorised() && inputs.stride <= 0x0FFFFFFFu &&
      (inputs.emitters == nullptr || inputs.emitters->triangles().size() <= kMostEmitterTriangles))
    k = eight_at_a_time(inputs, out);
  for (; k < inputs.count; ++k) one_vertex(inputs, k, out);
}

} // namespace specula::detail
