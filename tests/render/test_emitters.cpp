// The area lights (render/emitters.h, trace/area_lights.h): power-proportional picking, light
// sampling densities that integrate to one over each emitter, sample densities that agree with
// area_light_pdf, a table that follows moves and material edits, degenerate triangles left out.

#include "../trace/scene_builder.h"
#include "specula/trace/area_lights.h"
#include "specula/trace/sampler.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

namespace specula {
namespace {

Material emitting(const vec3& emission) {
  Material m;
  m.base_color = vec3(0.0f);
  m.emission = emission;
  return m;
}

/// A one-quad plane (two triangles) of edge `size`.
MeshSource quad(float size) { return test::primitive("plane", 1.0f, vec3(size), 32, 1); }

/// The instance slot of an entity in the layer.
std::uint32_t slot(const test::TracedWorld& w, ecs::Entity e) { return *w.layer.instance_of(e); }

/// Total picking probability of an instance's triangles.
double instance_pick(const EmitterTable& table, std::uint32_t instance) {
  double sum = 0.0;
  for (const EmitterTriangle& e : table.triangles())
    if (e.instance == instance) sum += e.pick;
  return sum;
}

TEST(Emitters, PickingFrequenciesFollowPower) {
  ecs::Registry reg;
  // Power = mean emission × area: a is 1 × 1, b is 0.5 × 4 (twice a's).
  const ecs::Entity a = test::add_mesh(reg, quad(1.0f), test::at(vec3(0, 2, 0)), emitting(vec3(1)));
  const ecs::Entity b =
      test::add_mesh(reg, quad(2.0f), test::at(vec3(3, 2, 0)), emitting(vec3(0.5f, 0.25f, 0.75f)));
  test::add_mesh(reg, test::primitive("box"), test::at(vec3(0))); // not an emitter
  const test::TracedWorld w(reg);
  const EmitterTable& table = w.layer.emitters();
  ASSERT_EQ(table.triangles().size(), 4u);
  EXPECT_NEAR(table.total_power(), 3.0, 1e-5);
  EXPECT_NEAR(instance_pick(table, slot(w, a)), 1.0 / 3.0, 1e-6);
  EXPECT_NEAR(instance_pick(table, slot(w, b)), 2.0 / 3.0, 1e-6);
  EXPECT_TRUE(table.features().area_lights);
  // Drawn frequencies against the picking probabilities: chi-square over the 4 triangles (3
  // degrees of freedom; 16.27 is the 0.1 % quantile, and the seed is fixed).
  constexpr int kDraws = 200000;
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  std::vector<int> count(table.triangles().size(), 0);
  for (int k = 0; k < kDraws; ++k) ++count[table.pick(uniform(rng))];
  double chi2 = 0.0;
  for (std::size_t k = 0; k < count.size(); ++k) {
    const double expected = kDraws * double(table.triangles()[k].pick);
    chi2 += (count[k] - expected) * (count[k] - expected) / expected;
  }
  EXPECT_LT(chi2, 16.27);
  // The ends of [0, 1) pick the first and the last triangle.
  EXPECT_EQ(table.pick(0.0f), 0u);
  EXPECT_EQ(table.pick(0x1.fffffep-1f), 3u);
}

TEST(Emitters, PickIsTheFirstTriangleWhoseCdfExceedsU) {
  // pick's branch-free search against its definition, for tables of 1 to 7 emitters (2 to 14
  // triangles) of unequal power: at random u, at every cdf and one ulp either side of it, at the
  // ends of [0, 1).
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  for (int emitters = 1; emitters <= 7; ++emitters) {
    ecs::Registry reg;
    for (int e = 0; e < emitters; ++e)
      test::add_mesh(reg, quad(0.5f + 0.37f * float(e)), test::at(vec3(2.0f * float(e), 2, 0)),
                     emitting(vec3(1.0f + float(e % 3))));
    const test::TracedWorld w(reg);
    const EmitterTable& table = w.layer.emitters();
    const std::vector<EmitterTriangle>& t = table.triangles();
    ASSERT_EQ(t.size(), std::size_t(2 * emitters));
    const auto expected = [&](float u) {
      const auto it = std::upper_bound(t.begin(), t.end(), u,
                                       [](float v, const EmitterTriangle& e) { return v < e.cdf; });
      return std::uint32_t(it == t.end() ? t.size() - 1 : std::size_t(it - t.begin()));
    };
    std::vector<float> us{0.0f, 0x1.fffffep-1f};
    for (const EmitterTriangle& e : t)
      for (const float u : {std::nextafter(e.cdf, 0.0f), e.cdf, std::nextafter(e.cdf, 2.0f)})
        if (u < 1.0f) us.push_back(u);
    for (int i = 0; i < 1000; ++i) us.push_back(uniform(rng));
    for (const float u : us)
      ASSERT_EQ(table.pick(u), expected(u)) << emitters << " emitters, u " << u;
  }
}

/// Where the ray from p along unit d meets triangle e (Möller–Trumbore, in double), if it does.
std::optional<vec3> hit_triangle(const EmitterTriangle& e, const dvec3& p, const dvec3& d) {
  const dvec3 e1(e.e1), e2(e.e2);
  const dvec3 h = glm::cross(d, e2);
  const double det = glm::dot(e1, h);
  if (std::abs(det) < 1e-300) return std::nullopt;
  const dvec3 s = p - dvec3(e.p0);
  const double u = glm::dot(s, h) / det;
  if (u < 0.0 || u > 1.0) return std::nullopt;
  const dvec3 q = glm::cross(s, e1);
  const double v = glm::dot(d, q) / det;
  if (v < 0.0 || u + v > 1.0) return std::nullopt;
  const double t = glm::dot(e2, q) / det;
  if (t <= 0.0) return std::nullopt;
  return vec3(p + t * d);
}

TEST(Emitters, TheLightSamplingDensityIntegratesToOneOverEachEmitter) {
  ecs::Registry reg;
  test::add_mesh(reg, quad(1.0f), test::at(vec3(0, 1, 0)), emitting(vec3(2, 1, 1)));
  test::add_mesh(reg, quad(1.5f),
                 test::at(vec3(1.2f, 0.3f, -0.4f), vec3(1), glm::angleAxis(1.1f, vec3(1, 0, 0.4f))),
                 emitting(vec3(1, 3, 1)), Kinematics::Type::Free);
  const test::TracedWorld w(reg);
  const EmitterTable& table = w.layer.emitters();
  ASSERT_EQ(table.triangles().size(), 4u);
  const vec3 p(0.2f, -0.3f, 0.1f);
  // ∫ over the sphere of pdf(ω) restricted to triangle k = its picking probability: estimated
  // with uniform directions as the mean of 4π · pdf · [the ray meets k], with its standard error.
  constexpr int kDirections = 400000;
  std::mt19937 rng(5);
  std::normal_distribution<double> gauss;
  const std::size_t n = table.triangles().size();
  std::vector<double> sum(n, 0.0), sum2(n, 0.0);
  for (int i = 0; i < kDirections; ++i) {
    const dvec3 d = glm::normalize(dvec3(gauss(rng), gauss(rng), gauss(rng)));
    for (std::size_t k = 0; k < n; ++k) {
      const EmitterTriangle& e = table.triangles()[k];
      if (const std::optional<vec3> q = hit_triangle(e, dvec3(p), d)) {
        const double f = 4.0 * std::numbers::pi * area_light_pdf(e, p, *q);
        sum[k] += f;
        sum2[k] += f * f;
      }
    }
  }
  for (std::size_t k = 0; k < n; ++k) {
    const double mean = sum[k] / kDirections;
    const double error = std::sqrt((sum2[k] / kDirections - mean * mean) / kDirections);
    const double pick = table.triangles()[k].pick;
    EXPECT_LT(error, 0.03 * pick) << "the check must be sharp enough to mean something";
    EXPECT_NEAR(mean / pick, 1.0, 4.0 * error / pick) << "triangle " << k;
  }
}

TEST(Emitters, ASampleCarriesTheDensityAreaLightPdfGivesItsPoint) {
  ecs::Registry reg;
  test::add_mesh(reg, quad(1.0f), test::at(vec3(0, 2, 0)), emitting(vec3(1)));
  test::add_mesh(reg, test::primitive("sphere", 0.5f, vec3(1), 12, 6), test::at(vec3(2, 1, 0)),
                 emitting(vec3(0.2f, 0.4f, 0.1f)), Kinematics::Type::Free);
  const test::TracedWorld w(reg);
  const EmitterTable& table = w.layer.emitters();
  const PixelSampler sampler(3, 1);
  for (const vec3 p : {vec3(0.1f, 0.0f, 0.2f), vec3(2.0f, 3.0f, -1.0f), vec3(-4, 2, 5)})
    for (std::uint32_t k = 0; k < 512; ++k) {
      const vec4 u = sampler.get4(k, 0);
      const AreaLightSample s = sample_area_light(table, p, u.x, u.y, u.z);
      ASSERT_NE(s.triangle, EmitterTable::kNone);
      const EmitterTriangle& e = table.triangles()[s.triangle];
      EXPECT_GT(e.pick, 0.0f);
      EXPECT_EQ(s.emission, e.emission);
      // On the triangle: in its plane, barycentrics within [0, 1].
      const vec3 r = s.position - e.p0;
      EXPECT_NEAR(glm::dot(r, e.normal), 0.0f, 1e-5f);
      if (s.pdf == 0.0f) continue; // seen edge-on
      EXPECT_NEAR(s.pdf, area_light_pdf(e, p, s.position), 1e-4f * s.pdf);
      EXPECT_NEAR(glm::length(s.to_light), 1.0f, 1e-5f);
      EXPECT_NEAR(s.distance, glm::length(s.position - p), 1e-5f * s.distance);
    }
}

TEST(Emitters, TheTableFollowsMovesAndMaterialEdits) {
  ecs::Registry reg;
  const ecs::Entity free = test::add_mesh(reg, quad(1.0f), test::at(vec3(0, 2, 0)),
                                          emitting(vec3(1)), Kinematics::Type::Free);
  const ecs::Entity parent = reg.create();
  reg.emplace<Transform>(parent, test::at(vec3(5, 0, 0)));
  const ecs::Entity child = test::add_mesh(reg, quad(1.0f), test::at(vec3(0, 3, 0)),
                                           emitting(vec3(2)), Kinematics::Type::Hierarchical);
  reg.emplace<Parent>(child, Parent{parent});
  test::TracedWorld w(reg);
  const auto first_point = [&](ecs::Entity e) {
    const EmitterTable& table = w.layer.emitters();
    const std::uint32_t k = table.find(slot(w, e), 0);
    EXPECT_NE(k, EmitterTable::kNone);
    return k == EmitterTable::kNone ? vec3(NAN) : table.triangles()[k].p0;
  };
  const vec3 free0 = first_point(free), child0 = first_point(child);
  EXPECT_NEAR(child0.x - free0.x, 5.0f, 1e-5f);

  reg.get<Transform>(free).translation = vec3(1, 2.5f, 0); // a free emitter moves
  w.update(reg);
  EXPECT_NEAR(glm::distance(first_point(free), free0 + vec3(1, 0.5f, 0)), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::distance(first_point(child), child0), 0.0f, 1e-5f);

  reg.get<Transform>(parent).translation = vec3(5, 0, -2); // a hierarchical one with its parent
  w.update(reg);
  EXPECT_NEAR(glm::distance(first_point(child), child0 + vec3(0, 0, -2)), 0.0f, 1e-5f);

  // A material edit: brighter, then dark (no longer an emitter at all).
  const double before = w.layer.emitters().total_power();
  reg.patch<Material>(child, [](Material& m) { m.emission = vec3(4); });
  w.update(reg);
  EXPECT_NEAR(w.layer.emitters().total_power(), before + 2.0, 1e-5);
  EXPECT_EQ(w.layer.emitters().triangles()[w.layer.emitters().find(slot(w, child), 1)].emission,
            vec3(4));
  reg.patch<Material>(child, [](Material& m) { m.emission = vec3(0); });
  w.update(reg);
  EXPECT_EQ(w.layer.emitters().find(slot(w, child), 0), EmitterTable::kNone);
  EXPECT_EQ(w.layer.emitters().triangles().size(), 2u);
  EXPECT_NEAR(instance_pick(w.layer.emitters(), slot(w, free)), 1.0, 1e-6);
  reg.patch<Material>(free, [](Material& m) { m.emission = vec3(0); });
  w.update(reg);
  EXPECT_TRUE(w.layer.emitters().empty());
  EXPECT_FALSE(w.layer.emitters().features().area_lights);
}

TEST(Emitters, DegenerateTrianglesAreNeverPicked) {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {2, 0, 0}, {1, 0, 1}, {3, 0, 0}};
  // Degenerate first (collinear), in the middle (a repeated vertex) and last.
  m.triangles = {{0, 1, 3}, {0, 2, 1}, {1, 1, 4}, {1, 2, 4}, {0, 3, 5}};
  m.compute_vertex_normals();
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, test::at(vec3(0)));
  reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(m), MeshSource{}, {}, 0});
  reg.emplace<Material>(e, emitting(vec3(1)));
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Static});
  const test::TracedWorld w(reg);
  const EmitterTable& table = w.layer.emitters();
  ASSERT_EQ(table.triangles().size(), 5u) << "degenerate ones keep their place (find)";
  for (const std::uint32_t k : {0u, 2u, 4u}) {
    EXPECT_EQ(table.triangles()[k].pick, 0.0f);
    // A density for them, were one asked for, is 0, not 0/0.
    EXPECT_EQ(area_light_pdf(table.triangles()[k], vec3(0, 1, 0), vec3(0.5f, 0, 0)), 0.0f);
  }
  EXPECT_NEAR(table.triangles()[1].pick + table.triangles()[3].pick, 1.0f, 1e-6f);
  // Every u, the interval ends included, picks a triangle with an area.
  std::vector<float> us = {0.0f, 0x1.fffffep-1f, 1.0f};
  for (const EmitterTriangle& t : table.triangles())
    us.insert(us.end(), {t.cdf, std::nextafter(t.cdf, 0.0f), std::nextafter(t.cdf, 1.0f)});
  for (int k = 0; k < 10000; ++k) us.push_back(float(k) / 10000.0f);
  for (const float u : us) {
    const std::uint32_t k = table.pick(u);
    ASSERT_LT(k, table.triangles().size());
    EXPECT_GT(table.triangles()[k].area, 0.0f) << "u " << u << " picked " << k;
  }
}

} // namespace
} // namespace specula
