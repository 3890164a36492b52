// Reflection, refraction and Fresnel: the laws they implement, on seeded random directions.

#include "specula/trace/optics.h"

#include <gtest/gtest.h>

#include <random>

namespace specula {
namespace {

vec3 random_unit(std::mt19937& rng) {
  std::normal_distribution<float> g;
  vec3 v;
  do v = vec3(g(rng), g(rng), g(rng)); while (glm::length(v) < 1e-3f);
  return glm::normalize(v);
}

/// A unit direction arriving at a surface with normal n (dot(d, n) < 0).
vec3 incoming(std::mt19937& rng, const vec3& n) {
  vec3 d = random_unit(rng);
  if (glm::dot(d, n) > 0.0f) d = -d;
  return d;
}

TEST(Optics, ReflectionPreservesTheAngleAndStaysInThePlaneOfIncidence) {
  std::mt19937 rng(7);
  for (int i = 0; i < 10000; ++i) {
    const vec3 n = random_unit(rng);
    const vec3 d = incoming(rng, n);
    const vec3 r = reflect_direction(d, n);
    EXPECT_NEAR(glm::dot(r, n), -glm::dot(d, n), 1e-5f);
    EXPECT_NEAR(glm::length(r), 1.0f, 1e-5f);
    EXPECT_NEAR(glm::dot(glm::cross(d, n), r), 0.0f, 1e-5f); // coplanar with d and n
  }
}

TEST(Optics, RefractionObeysSnellsLaw) {
  std::mt19937 rng(11);
  for (const float eta : {1.0f / 1.5f, 1.0f / 1.33f, 1.0f, 1.33f, 1.5f}) {
    for (int i = 0; i < 5000; ++i) {
      const vec3 n = random_unit(rng);
      const vec3 d = incoming(rng, n);
      const auto t = refract_direction(d, n, eta);
      const float sin_i = glm::length(glm::cross(d, n));
      if (eta * sin_i >= 1.0f) {
        EXPECT_FALSE(t.has_value());
        continue;
      }
      ASSERT_TRUE(t.has_value());
      EXPECT_NEAR(glm::length(*t), 1.0f, 1e-5f);
      EXPECT_LT(glm::dot(*t, n), 0.0f); // continues through the surface
      EXPECT_NEAR(eta * sin_i, glm::length(glm::cross(*t, n)), 2e-4f);
      EXPECT_NEAR(glm::dot(glm::cross(d, n), *t), 0.0f, 1e-4f);
    }
  }
}

TEST(Optics, TotalInternalReflectionBeyondTheCriticalAngle) {
  const float ior = 1.5f;
  const float critical = std::asin(1.0f / ior);
  const vec3 n(0, 0, 1);
  for (const float delta : {-0.05f, -0.001f, 0.001f, 0.05f, 0.5f}) {
    const float theta = critical + delta;
    if (theta >= 0.5f * 3.14159265f) continue;
    const vec3 d(std::sin(theta), 0.0f, -std::cos(theta)); // inside glass, heading out
    const auto t = refract_direction(d, n, ior);
    const float f = fresnel_dielectric(std::cos(theta), ior);
    if (delta > 0.0f) {
      EXPECT_FALSE(t.has_value()) << delta;
      EXPECT_EQ(f, 1.0f) << delta;
    } else {
      EXPECT_TRUE(t.has_value()) << delta;
      EXPECT_LT(f, 1.0f) << delta;
    }
  }
}

TEST(Optics, FresnelMatchesTheNormalIncidenceFormulaAndGrowsToOneAtGrazing) {
  for (const float ior : {1.33f, 1.5f, 2.4f}) {
    const float r0 = ((1.0f - ior) / (1.0f + ior)) * ((1.0f - ior) / (1.0f + ior));
    EXPECT_NEAR(fresnel_dielectric(1.0f, 1.0f / ior), r0, 1e-6f);
    EXPECT_NEAR(fresnel_dielectric(1.0f, ior), r0, 1e-6f); // same from inside at normal incidence
    EXPECT_NEAR(fresnel_dielectric(0.0f, 1.0f / ior), 1.0f, 1e-6f);
    float previous = 0.0f;
    for (int i = 0; i <= 100; ++i) { // monotone in the angle from outside
      const float f = fresnel_dielectric(1.0f - float(i) / 100.0f, 1.0f / ior);
      EXPECT_GE(f + 1e-6f, previous);
      EXPECT_LE(f, 1.0f);
      previous = f;
    }
  }
  EXPECT_NEAR(fresnel_dielectric(0.7f, 1.0f), 0.0f, 1e-7f); // no interface, no reflection
}

} // namespace
} // namespace specula
