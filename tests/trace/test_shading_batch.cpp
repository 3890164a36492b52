// A wave's shading points at once (trace/shading_batch.h): the AVX2 code and the one-at-a-time
// code must give shading_point's bits for every hit, on hard hits too — barycentrics on and just
// outside the edges and vertices, NaN and huge ones, hits near an edge that need the inset, both
// sides of the surface, baked and transformed instances, smooth and flat meshes, misses between.

#include "scene_builder.h"
#include "specula/render/scene_layer.h"
#include "specula/systems/animation_system.h"
#include "specula/systems/transform_system.h"
#include "specula/trace/shading_batch.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace specula {
namespace {

const SceneLayer& synced(ecs::Registry& reg, SceneLayer& layer) {
  FrameContext ctx;
  ctx.tick = 1;
  ctx.dt = 1.0 / 60.0;
  animation_system(reg, ctx);
  transform_system(reg, ctx);
  layer.sync(reg);
  return layer;
}

/// Static (baked) and free (transformed) instances, smooth spheres and flat boxes, far from the
/// origin and tiny.
void scene(ecs::Registry& reg) {
  using test::add_mesh;
  using test::at;
  using test::primitive;
  const quat turned = glm::angleAxis(0.7f, glm::normalize(vec3(1.0f, 2.0f, 0.5f)));
  add_mesh(reg, primitive("sphere", 1.0f, vec3(1.0f), 12, 6), at(vec3(0.0f)));
  add_mesh(reg, primitive("box", 1.0f, vec3(2.0f, 1.0f, 0.5f)), at(vec3(3.0f, 0.0f, 0.0f)));
  add_mesh(reg, primitive("plane", 1.0f, vec3(4.0f)), at(vec3(0.0f, -1.0f, 0.0f)));
  add_mesh(reg, primitive("sphere", 1e-3f, vec3(1.0f), 8, 4), at(vec3(1e4f, 2e4f, -3e4f)));
  add_mesh(reg, primitive("sphere", 0.5f, vec3(1.0f), 10, 5),
           at(vec3(-2.0f, 1.0f, 0.0f), vec3(1.0f, 2.0f, 0.5f), turned), Material{},
           Kinematics::Type::Free);
  add_mesh(reg, primitive("box", 1.0f, vec3(1.0f)), at(vec3(0.0f, 3.0f, 1.0f), vec3(0.3f), turned),
           Material{}, Kinematics::Type::Free);
}

/// Barycentrics for hit k: random inside, then the hard ones.
vec2 barycentrics(std::mt19937& rng, std::uint32_t k) {
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  constexpr float kUlp = std::numeric_limits<float>::epsilon();
  switch (k % 12) {
  case 0:
    return vec2(0.0f, 0.0f); // a vertex
  case 1:
    return vec2(1.0f, 0.0f);
  case 2:
    return vec2(0.5f, 0.5f); // an edge midpoint
  case 3:
    return vec2(-1e-7f, 0.3f); // just outside
  case 4:
    return vec2(0.6f, 0.4f + kUlp); // u + v just over 1
  case 5:
    return vec2(1e-6f, 0.5f); // near an edge: the inset
  case 6:
    return vec2(std::numeric_limits<float>::quiet_NaN(), 0.2f);
  case 7:
    return vec2(3.0f, -2.0f);
  default: {
    const float u = unit(rng), v = unit(rng);
    return u + v <= 1.0f ? vec2(u, v) : vec2(1.0f - u, 1.0f - v);
  }
  }
}

void expect_same_bits(const vec3& a, const vec3& b, const char* what, std::size_t i) {
  for (int c = 0; c < 3; ++c)
    EXPECT_EQ(std::bit_cast<std::uint32_t>(a[c]), std::bit_cast<std::uint32_t>(b[c]))
        << what << "[" << c << "] of hit " << i << ": " << a[c] << " against " << b[c];
}

TEST(ShadingBatch, EveryHitGetsShadingPointsBitsWithAndWithoutSimd) {
  ecs::Registry reg;
  scene(reg);
  SceneLayer layer;
  const SceneTables& tables = synced(reg, layer).tables();
  std::mt19937 rng(20261128);
  std::uniform_real_distribution<float> signed_unit(-1.0f, 1.0f);
  std::vector<Hit> hits;
  std::vector<vec3> directions;
  bool baked = false, transformed = false;
  for (std::uint32_t slot = 0; slot < tables.instances.size(); ++slot) {
    const gpu::GpuInstance& inst = tables.instances[slot];
    const gpu::GpuMesh& mesh = tables.meshes[inst.mesh];
    ((inst.flags & gpu::kInstanceIdentity) != 0 ? baked : transformed) = true;
    for (std::uint32_t k = 0; k < 3 * mesh.triangle_count; ++k) {
      Hit hit;
      hit.primitive = k % mesh.triangle_count;
      hit.instance = slot;
      hit.t = 1.0f;
      hit.uv = barycentrics(rng, k);
      const uvec3 tri = tables.triangles[mesh.first_triangle + hit.primitive];
      const vec3* p = tables.positions.data() + mesh.first_vertex;
      hit.object_normal = glm::cross(p[tri.y] - p[tri.x], p[tri.z] - p[tri.x]);
      hits.push_back(hit);
      // Either side of the surface.
      directions.push_back(
          glm::normalize(vec3(signed_unit(rng), signed_unit(rng), signed_unit(rng)) + vec3(1e-3f)));
      if (k % 5 == 0) { // a miss between
        hits.push_back(Hit{});
        directions.push_back(vec3(0.0f, 0.0f, 1.0f));
      }
    }
  }
  ASSERT_TRUE(baked && transformed);
  ASSERT_GT(hits.size(), 600u);
  // The directions as a vec3 array, as a wave's rays (eight words apart) and as three arrays
  // (PrimaryHits).
  std::vector<Ray> rays(directions.size());
  std::vector<float> dx, dy, dz;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    rays[i].direction = directions[i];
    dx.push_back(directions[i].x);
    dy.push_back(directions[i].y);
    dz.push_back(directions[i].z);
  }
  const detail::Directions layouts[] = {
      detail::Directions::aos(reinterpret_cast<const float*>(directions.data()), 3),
      detail::Directions::aos(&rays[0].direction.x, sizeof(Ray) / sizeof(float)),
      detail::Directions{dx.data(), dy.data(), dz.data(), 1}};
  for (const bool simd : {false, true})
    for (const detail::Directions& dirs : layouts) {
      const std::size_t stride = dirs.stride;
      ShadingPoint marker;
      marker.position = vec3(-7.0f);
      std::vector<ShadingPoint> out(hits.size(), marker);
      const std::size_t vectorised = detail::shading_points(tables, hits, dirs, out, simd);
      if (!simd) {
        EXPECT_EQ(vectorised, 0u);
      }
      // Most hits are interior ones on baked instances: the vector code must have taken many, or
      // this compared the scalar code with itself.
      if (simd && detail::shading_points_vectorised()) {
        EXPECT_GT(vectorised, hits.size() / 8);
      }
      for (std::size_t i = 0; i < hits.size(); ++i) {
        if (!hits[i].hit()) {
          EXPECT_EQ(out[i].position, marker.position) << "a miss's entry was written";
          continue;
        }
        const ShadingPoint want = shading_point(tables, hits[i], directions[i]);
        const ShadingPoint& got = out[i];
        expect_same_bits(got.position, want.position, "position", i);
        expect_same_bits(got.spawn_point, want.spawn_point, "spawn_point", i);
        expect_same_bits(got.spawn_error, want.spawn_error, "spawn_error", i);
        expect_same_bits(got.geometric_normal, want.geometric_normal, "geometric_normal", i);
        expect_same_bits(got.shading_normal, want.shading_normal, "shading_normal", i);
        EXPECT_EQ(got.front_face, want.front_face) << "hit " << i;
        if (::testing::Test::HasFailure()) {
          ADD_FAILURE() << "with simd " << simd << ", stride " << stride;
          return;
        }
      }
    }
}

TEST(ShadingBatch, HitsTheVectorCodeCannotTakeAreLeftToTheScalarCode) {
  if (!detail::shading_points_vectorised()) GTEST_SKIP() << "this CPU has no AVX2";
  ecs::Registry reg;
  scene(reg);
  SceneLayer layer;
  const SceneTables& tables = synced(reg, layer).tables();
  // Eight interior hits on a baked box, then the same on a transformed box, then baked ones on an
  // edge (the inset) and outside the triangle.
  std::vector<Hit> hits;
  const auto add = [&](bool identity, vec2 uv) {
    for (std::uint32_t slot = 0; slot < tables.instances.size(); ++slot)
      if (((tables.instances[slot].flags & gpu::kInstanceIdentity) != 0) == identity &&
          tables.meshes[tables.instances[slot].mesh].triangle_count == 12) {
        for (std::uint32_t k = 0; k < 8; ++k) {
          Hit hit;
          hit.instance = slot;
          hit.primitive = k;
          hit.t = 1.0f;
          hit.uv = uv;
          hit.object_normal = vec3(0.0f, 1.0f, 0.0f);
          hits.push_back(hit);
        }
        return;
      }
  };
  add(true, vec2(0.3f, 0.3f));
  add(false, vec2(0.3f, 0.3f));
  add(true, vec2(0.0f, 0.5f));
  add(true, vec2(0.7f, 0.7f));
  ASSERT_EQ(hits.size(), 32u);
  const std::vector<vec3> directions(hits.size(), glm::normalize(vec3(0.2f, -1.0f, 0.3f)));
  std::vector<ShadingPoint> out(hits.size());
  EXPECT_EQ(detail::shading_points(
                tables, hits,
                detail::Directions::aos(reinterpret_cast<const float*>(directions.data()), 3), out),
            8u);
  for (std::size_t i = 0; i < hits.size(); ++i)
    expect_same_bits(out[i].spawn_point, shading_point(tables, hits[i], directions[i]).spawn_point,
                     "spawn_point", i);
}

} // namespace
} // namespace specula
