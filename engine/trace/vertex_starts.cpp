// What a wave's path vertices start from (vertex_starts.h): offset_ray_origin and
// sample_area_light, one vertex at a time, or eight at a time with AVX2 repeating their operations
// in their order (tests/trace/test_vertex_starts.cpp compares the two bit for bit).

#include "specula/trace/vertex_starts.h"

#include "specula/core/assert.h"
#include "specula/geometry/ray_offset.h"
#include "specula/trace/area_lights.h"
#include "specula/trace/lanes_avx2.h"
#include "specula/trace/lights.h"

#include <cstddef>
#include <limits>
#include <type_traits>

namespace specula::detail {

void VertexStarts::resize(std::size_t vertices, std::size_t lights) {
  for (std::vector<float>* v : {&ox, &oy, &oz, &lx, &ly, &lz, &distance, &pdf, &er, &eg, &eb})
    v->resize(vertices);
  for (std::vector<float>* v : {&plx, &ply, &plz, &pir, &pig, &pib, &ptfar})
    v->resize(vertices * lights);
}

namespace {

using namespace avx2;

/// Light l's sample at vertex k (shading point sp, ray origin `origin`), one at a time.
void one_punctual(const VertexInputs& in, std::size_t l, std::size_t k, const ShadingPoint& sp,
                  const vec3& origin, VertexStarts& out) {
  const gpu::GpuLight& light = in.lights[l];
  const LightSample ls = sample_light(light, sp.position);
  const std::size_t e = l * in.count + k;
  out.plx[e] = ls.to_light.x;
  out.ply[e] = ls.to_light.y;
  out.plz[e] = ls.to_light.z;
  out.pir[e] = ls.irradiance.x;
  out.pig[e] = ls.irradiance.y;
  out.pib[e] = ls.irradiance.z;
  out.ptfar[e] = shadow_tfar(light, ls, origin);
}

/// Vertex k, one at a time.
void one_vertex(const VertexInputs& in, std::size_t k, VertexStarts& out) {
  const std::size_t i = k / in.per_point;
  if (!in.hits[i].hit()) return;
  const ShadingPoint& sp = in.points[i];
  const vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
  out.ox[k] = origin.x;
  out.oy[k] = origin.y;
  out.oz[k] = origin.z;
  for (std::size_t l = 0; l < in.lights.size(); ++l) one_punctual(in, l, k, sp, origin, out);
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

/// Four lanes of a float register as doubles (half 0: lanes 0-3, 1: lanes 4-7).
SPECULA_AVX2 inline __m256d wide(__m256 x, int half) {
  return _mm256_cvtps_pd(half == 0 ? _mm256_castps256_ps128(x) : _mm256_extractf128_ps(x, 1));
}

SPECULA_AVX2 inline __m256d dot_d(__m256d x, __m256d y, __m256d z) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(x, x), _mm256_mul_pd(y, y)),
                       _mm256_mul_pd(z, z));
}

/// A point light without a range (sample_light's inverse-square branch, in double as there, and
/// shadow_tfar) at vertices k0 … k0 + 7 (positions `p`, ray origins `origin`): entry e0 on.
SPECULA_AVX2 void point_light8(const gpu::GpuLight& light, const V3& p, const V3& origin,
                               std::size_t e0, VertexStarts& out) {
  const V3 at{_mm256_set1_ps(light.position.x), _mm256_set1_ps(light.position.y),
              _mm256_set1_ps(light.position.z)};
  const V3 d = sub(at, p);      // to the light, in float as sample_light takes it
  const V3 a = sub(at, origin); // shadow_tfar's
  const __m256d zero = _mm256_setzero_pd();
  const __m256d cap = _mm256_set1_pd(double(kMaxIrradiance));
  const __m256d intensity[3] = {_mm256_set1_pd(double(light.intensity.x)),
                                _mm256_set1_pd(double(light.intensity.y)),
                                _mm256_set1_pd(double(light.intensity.z))};
  __m128 to[3][2], irr[3][2], distance[2], length[2];
  int placed = 0; // bit per lane: dist > 0
  for (int h = 0; h < 2; ++h) {
    const __m256d dx = wide(d.x, h), dy = wide(d.y, h), dz = wide(d.z, h);
    const __m256d dist = _mm256_sqrt_pd(dot_d(dx, dy, dz));
    placed |= _mm256_movemask_pd(_mm256_cmp_pd(dist, zero, _CMP_GT_OQ)) << (4 * h);
    distance[h] = _mm256_cvtpd_ps(dist);
    const __m256d dc[3] = {dx, dy, dz};
    for (int c = 0; c < 3; ++c) {
      to[c][h] = _mm256_cvtpd_ps(_mm256_div_pd(dc[c], dist));
      // I · 1 / d / d (an attenuation of 1 changes nothing), capped: glm::min(e, cap).
      const __m256d e = _mm256_div_pd(_mm256_div_pd(intensity[c], dist), dist);
      irr[c][h] = _mm256_cvtpd_ps(_mm256_min_pd(cap, e));
    }
    length[h] = _mm256_cvtpd_ps(
        _mm256_mul_pd(_mm256_sqrt_pd(dot_d(wide(a.x, h), wide(a.y, h), wide(a.z, h))),
                      _mm256_set1_pd(1.0 - 1e-5)));
  }
  // Where sample_light gives up (the point on the light, or NaN): no direction or irradiance, an
  // infinite distance.
  const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  const __m256 ok = _mm256_castsi256_ps(
      _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(placed), bit), bit));
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  const __m256 dist = _mm256_blendv_ps(inf, _mm256_set_m128(distance[1], distance[0]), ok);
  float* columns[3][2] = {{out.plx.data(), out.pir.data()},
                          {out.ply.data(), out.pig.data()},
                          {out.plz.data(), out.pib.data()}};
  for (int c = 0; c < 3; ++c) {
    _mm256_storeu_ps(columns[c][0] + e0, _mm256_and_ps(ok, _mm256_set_m128(to[c][1], to[c][0])));
    _mm256_storeu_ps(columns[c][1] + e0, _mm256_and_ps(ok, _mm256_set_m128(irr[c][1], irr[c][0])));
  }
  // shadow_tfar: the distance itself where it is infinite.
  _mm256_storeu_ps(out.ptfar.data() + e0,
                   _mm256_blendv_ps(_mm256_set_m128(length[1], length[0]), dist,
                                    _mm256_cmp_ps(dist, inf, _CMP_EQ_OQ)));
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
  const V3 origin{round_away(po.x, n.x), round_away(po.y, n.y), round_away(po.z, n.z)};
  _mm256_storeu_ps(out.ox.data() + k0, origin.x);
  _mm256_storeu_ps(out.oy.data() + k0, origin.y);
  _mm256_storeu_ps(out.oz.data() + k0, origin.z);

  // The punctual lights: point lights without a range eight at a time, the others one by one.
  for (std::size_t l = 0; l < in.lights.size(); ++l) {
    const gpu::GpuLight& light = in.lights[l];
    if (light.type == gpu::kLightPoint && !(light.range > 0.0f)) {
      point_light8(light, position, origin, l * in.count + k0, out);
      continue;
    }
    for (std::size_t k = k0; k < k0 + 8; ++k) {
      const std::size_t i = k / in.per_point;
      if (in.hits[i].hit()) one_punctual(in, l, k, in.points[i], out.origin(k), out);
    }
  }
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
  out.resize(in.count, in.lights.size());
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
