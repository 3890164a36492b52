// What a wave's path vertices start from (trace/vertex_starts.h): the AVX2 code and the
// one-at-a-time code must give offset_ray_origin's, sample_light's (with shadow_tfar) and
// sample_area_light's bits for every hit —
// on hard points too (on an emitter's corner and plane, behind it, far enough for the distance to
// overflow, normals with zero and negative components, zero and huge error bounds), with picks
// past the last cdf, with emitter tables small enough for registers and large ones, and with
// several vertices sharing a hit (a pixel's samples).

#include "scene_builder.h"
#include "specula/geometry/ray_offset.h"
#include "specula/trace/area_lights.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"
#include "specula/trace/vertex_starts.h"

#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

namespace specula {
namespace {

/// Emissive quads (two triangles each, or 512 with `fine`) of unequal power.
void emitters(ecs::Registry& reg, int quads, bool fine) {
  const vec3 at[] = {vec3(0, 2, 0), vec3(1.5f, 1, -1), vec3(3, 3, 3), vec3(-1, 2.5f, 1)};
  const vec3 axis[] = {vec3(1, 0, 0), vec3(1, 0, 1), vec3(1, 1, 0), vec3(0, 1, 1)};
  const float angle[] = {3.14159265f, 0.7f, 2.5f, 1.2f};
  for (int q = 0; q < quads; ++q) {
    Material m;
    m.base_color = vec3(0.0f);
    m.emission = vec3(1.0f + float(q), 2.0f, 0.5f * float(q + 1));
    test::add_mesh(
        reg, test::primitive("plane", 1.0f, vec3(0.5f + 0.4f * float(q)), 32, fine ? 16 : 1),
        test::at(at[q], vec3(1.0f), glm::angleAxis(angle[q], glm::normalize(axis[q]))), m);
  }
}

bool same_bits(float a, float b) {
  return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b);
}

gpu::GpuLight light(std::uint32_t type, const vec3& position, const vec3& intensity,
                    float range = 0.0f) {
  gpu::GpuLight l{};
  l.type = type;
  l.position = position;
  l.direction = glm::normalize(vec3(0.3f, -1.0f, 0.2f));
  l.intensity = intensity;
  l.range = range;
  l.cos_inner = 0.9f;
  l.cos_outer = 0.7f;
  return l;
}

/// Punctual lights: point lights without a range (the vector code's), near and far, one of
/// 1e20 cd (irradiance capped where a vertex sits 1e-6 from it), and the kinds left to the scalar
/// code (a range, a spot, a directional light).
std::vector<gpu::GpuLight> punctual_lights() {
  return {light(gpu::kLightPoint, vec3(0.0f, 1.85f, 0.0f), vec3(3.0f, 2.5f, 2.1f)),
          light(gpu::kLightPoint, vec3(-1.0f, 0.5f, 2.0f), vec3(1e20f)),
          light(gpu::kLightPoint, vec3(1e18f, 0.0f, -1e18f), vec3(5.0f, 0.0f, 1.0f)),
          light(gpu::kLightPoint, vec3(2.0f, 2.0f, 2.0f), vec3(1.0f), 3.0f),
          light(gpu::kLightSpot, vec3(0.0f, 3.0f, 0.0f), vec3(10.0f)),
          light(gpu::kLightDirectional, vec3(0.0f), vec3(0.7f))};
}

/// Random vertices around the emitters of `table` and the hard ones; `per_point` vertices share
/// each hit. Returns how many light samples were usable.
std::size_t expect_vector_equals_scalar(const EmitterTable& table, std::size_t per_point) {
  const std::vector<gpu::GpuLight> lights = punctual_lights();
  std::mt19937 rng(20261129);
  std::uniform_real_distribution<float> coordinate(-4.0f, 4.0f), unit(0.0f, 1.0f);
  std::normal_distribution<float> gauss;
  const auto direction = [&] { return glm::normalize(vec3(gauss(rng), gauss(rng), gauss(rng))); };
  constexpr std::size_t kPoints = 8 * 60 + 3; // a tail past the last group of eight
  std::vector<Hit> hits(kPoints);
  std::vector<ShadingPoint> points(kPoints);
  for (std::size_t i = 0; i < kPoints; ++i) {
    ShadingPoint& sp = points[i];
    const EmitterTriangle& e = table.triangles()[i % table.triangles().size()];
    sp.position = vec3(coordinate(rng), coordinate(rng), coordinate(rng));
    if (i % 11 == 0) sp.position = e.p0 + unit(rng) * 0.5f * e.e1 + unit(rng) * 0.5f * e.e2;
    if (i % 13 == 0) sp.position = e.p0;                       // distance 0 from a corner
    if (i % 17 == 0) sp.position = vec3(3e19f, -2e19f, 1e19f); // the distance overflows
    if (i % 31 == 0) sp.position = lights[0].position;         // on a point light
    if (i % 37 == 0) sp.position = lights[1].position + vec3(1e-6f, 0.0f, 0.0f);
    sp.spawn_point = sp.position + vec3(1e-6f);
    sp.spawn_error = i % 7 == 0 ? vec3(0.0f) : glm::abs(sp.position) * 1e-6f + vec3(1e-30f);
    sp.geometric_normal = direction();
    if (i % 5 == 0) sp.geometric_normal = vec3(0.0f, i % 10 == 0 ? 1.0f : -1.0f, 0.0f);
    if (i % 19 == 0) sp.spawn_point = vec3(0.0f, -0.0f, 3e38f);
    sp.shading_normal = sp.geometric_normal;
    hits[i].instance = i % 9 == 4 ? kNoInstance : 0u; // a miss now and then
    hits[i].t = 1.0f;
  }
  const std::size_t count = kPoints * per_point - per_point / 2;
  constexpr std::size_t kStride = 5; // the numbers sit in a wider record, as in VertexSamples
  std::vector<float> u(count * kStride, -1.0f);
  for (std::size_t k = 0; k < count; ++k) {
    for (int d = 0; d < 3; ++d) u[k * kStride + std::size_t(d)] = unit(rng);
    if (k % 23 == 0) u[k * kStride] = 0x1.fffffep-1f; // at or above every cdf: the fallback
    if (k % 29 == 0) u[k * kStride + 1] = 0.0f;       // the triangle's corner p0
  }
  detail::VertexInputs in{hits, points, per_point, count, &table, u.data(), kStride, lights};
  detail::VertexStarts vector, scalar;
  detail::vertex_starts(in, vector, true);
  detail::vertex_starts(in, scalar, false);
  std::size_t usable = 0;
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t i = k / per_point;
    if (!hits[i].hit()) continue;
    const ShadingPoint& sp = points[i];
    // The scalar code is the functions it stands for.
    const vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
    const float* uk = u.data() + k * kStride;
    const AreaLightSample ls = sample_area_light(table, sp.position, uk[0], uk[1], uk[2]);
    const float want[] = {origin.x,      origin.y,      origin.z,     ls.to_light.x,
                          ls.to_light.y, ls.to_light.z, ls.distance,  ls.pdf,
                          ls.emission.x, ls.emission.y, ls.emission.z};
    const detail::VertexStarts* outs[] = {&scalar, &vector};
    for (const detail::VertexStarts* o : outs) {
      const float got[] = {o->ox[k],       o->oy[k],  o->oz[k], o->lx[k], o->ly[k], o->lz[k],
                           o->distance[k], o->pdf[k], o->er[k], o->eg[k], o->eb[k]};
      for (std::size_t c = 0; c < std::size(want); ++c)
        EXPECT_TRUE(same_bits(got[c], want[c]))
            << (o == &vector ? "vector" : "scalar") << " column " << c << " of vertex " << k << ": "
            << got[c] << " against " << want[c];
      if (::testing::Test::HasFailure()) return usable;
      for (std::size_t l = 0; l < lights.size(); ++l) {
        const LightSample s = sample_light(lights[l], sp.position);
        const float tfar = shadow_tfar(lights[l], s, origin);
        const std::size_t e = l * count + k;
        const float want_l[] = {s.to_light.x,   s.to_light.y,   s.to_light.z, s.irradiance.x,
                                s.irradiance.y, s.irradiance.z, tfar};
        const float got_l[] = {o->plx[e], o->ply[e], o->plz[e],  o->pir[e],
                               o->pig[e], o->pib[e], o->ptfar[e]};
        for (std::size_t c = 0; c < std::size(want_l); ++c)
          EXPECT_TRUE(same_bits(got_l[c], want_l[c]))
              << (o == &vector ? "vector" : "scalar") << " light " << l << " column " << c
              << " of vertex " << k << ": " << got_l[c] << " against " << want_l[c];
        if (::testing::Test::HasFailure()) return usable;
      }
    }
    usable += ls.pdf > 0.0f ? 1 : 0;
  }
  return usable;
}

TEST(VertexStarts, VectorisedStartsEqualTheScalarOnesBitForBit) {
  if (!detail::vertex_starts_vectorised()) GTEST_SKIP() << "this CPU has no AVX2";
  // Tables of up to eight triangles are held in registers, larger ones read from memory.
  for (const auto& [quads, fine] : {std::pair{1, false}, std::pair{4, false}, std::pair{4, true}}) {
    ecs::Registry reg;
    emitters(reg, quads, fine);
    const test::TracedWorld w(reg);
    const EmitterTable& table = w.layer.emitters();
    ASSERT_EQ(table.triangles().size(), std::size_t(fine ? 512 * quads : 2 * quads));
    for (const std::size_t per_point : {std::size_t{1}, std::size_t{3}}) {
      SCOPED_TRACE(testing::Message()
                   << table.triangles().size() << " triangles, " << per_point << " vertices a hit");
      const std::size_t usable = expect_vector_equals_scalar(table, per_point);
      if (::testing::Test::HasFailure()) return;
      // Both kinds occur: the comparison covers usable samples and the early exits.
      EXPECT_GT(usable, 100u);
    }
  }
}

TEST(VertexStarts, WithoutLightsTheOriginsAreStillOffsetOffTheSurface) {
  std::vector<Hit> hits(21);
  std::vector<ShadingPoint> points(21);
  for (std::size_t i = 0; i < hits.size(); ++i) {
    hits[i].instance = 0;
    points[i].spawn_point = vec3(float(i), -2.0f, 0.5f);
    points[i].spawn_error = vec3(1e-6f);
    points[i].geometric_normal = vec3(0.0f, 0.0f, i % 2 == 0 ? 1.0f : -1.0f);
  }
  for (const bool simd : {false, true}) {
    detail::VertexStarts out;
    detail::VertexInputs in;
    in.hits = hits;
    in.points = points;
    in.count = hits.size();
    detail::vertex_starts(in, out, simd);
    for (std::size_t i = 0; i < hits.size(); ++i) {
      const vec3 want = offset_ray_origin(points[i].spawn_point, points[i].spawn_error,
                                          points[i].geometric_normal);
      EXPECT_EQ(out.origin(i), want) << "vertex " << i << " simd " << simd;
      // Off the surface, on the normal's side.
      EXPECT_EQ(out.origin(i).z > 0.5f, i % 2 == 0) << "vertex " << i;
    }
  }
}

} // namespace
} // namespace specula
