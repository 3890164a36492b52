#pragma once
/// \file
/// Area lights: every triangle of an instance whose material emits, in render space, with a
/// cumulative distribution proportional to its power (mean emission × area), so that light
/// sampling picks triangles power-proportionally (trace/area_lights.h). Emission is two-sided, as
/// in every integrator (cast and Whitted shade an emitter's either side with its emission). Built
/// by the scene layer whenever a sync changes anything, so it always matches the tables; also the
/// scene's features, for integrators that model only what a scene has.

#include "specula/core/math.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace specula {

struct SceneTables;

struct EmitterTriangle {
  vec3 p0;          ///< render space
  float area = 0.0f;
  vec3 e1;          ///< p1 − p0
  float cdf = 0.0f; ///< picking probability of this and every earlier triangle
  vec3 e2;          ///< p2 − p0
  float pick = 0.0f; ///< its own picking probability (power / total power)
  vec3 normal{0.0f}; ///< unit, along e1 × e2 (zero for a degenerate triangle)
  std::uint32_t instance = 0;
  vec3 emission;
  std::uint32_t primitive = 0;
};

/// What the scene has, for integrators specialised on it: a scene without dielectrics or area
/// lights takes no branch for them.
struct SceneFeatures {
  bool area_lights = false;  ///< some triangle emits (EmitterTable non-empty)
  bool punctual_lights = false;
  bool mirrors = false;      ///< some material has reflectivity > 0
  bool dielectrics = false;  ///< some material has transmission > 0
};

class EmitterTable {
public:
  /// Rebuilds from the tables: live instances whose material's emission is non-zero and whose
  /// triangles have a positive area (degenerate ones are left out: they emit nothing).
  void build(const SceneTables& tables);

  [[nodiscard]] bool empty() const { return triangles_.empty(); }
  [[nodiscard]] const std::vector<EmitterTriangle>& triangles() const { return triangles_; }
  /// The emitter triangle of (instance, primitive), or kNone when it does not emit.
  [[nodiscard]] std::uint32_t find(std::uint32_t instance, std::uint32_t primitive) const {
    if (instance >= first_.size() || first_[instance] == kNone) return kNone;
    return first_[instance] + primitive;
  }
  /// Index of the triangle whose CDF interval holds u ∈ [0, 1).
  [[nodiscard]] std::uint32_t pick(float u) const;
  [[nodiscard]] double total_power() const { return total_power_; }
  [[nodiscard]] const SceneFeatures& features() const { return features_; }

  static constexpr std::uint32_t kNone = 0xFFFFFFFFu;

private:
  std::vector<EmitterTriangle> triangles_;
  std::vector<std::uint32_t> first_; ///< per instance slot: its primitive 0's entry, or kNone
  double total_power_ = 0.0;
  SceneFeatures features_;
};

inline std::uint32_t EmitterTable::pick(float u) const {
  // The first triangle whose cdf exceeds u; zero-power triangles have an empty interval and are
  // never returned (their cdf equals their predecessor's). A branch-free binary search, inline:
  // u is random, so a branch on it would be mispredicted half the time.
  const EmitterTriangle* first = triangles_.data();
  std::size_t n = triangles_.size();
  while (n > 1) {
    const std::size_t half = n / 2;
    first = u < first[half].cdf ? first : first + half;
    n -= half;
  }
  if (n == 1 && !(u < first->cdf)) ++first; // past the end: u at or above every cdf
  const auto k = std::size_t(first - triangles_.data());
  if (k == triangles_.size()) {
    for (std::size_t j = triangles_.size(); j-- > 0;)
      if (triangles_[j].pick > 0.0f) return std::uint32_t(j);
  }
  return std::uint32_t(k);
}

} // namespace specula
