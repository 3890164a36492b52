#pragma once
#include "specula/core/math.h"

#include <cstdint>
#include <vector>

namespace specula {

/// Linear = lerp for vectors, slerp for rotations. KochanekBartels = the TCB spline of Kochanek
/// and Bartels (SIGGRAPH 1984) as BART uses it (animation_sampling.h): Hermite segments with
/// per-key tension/continuity/bias tangents for vectors, squad with the same tangents taken in
/// the quaternion logarithm for rotations. It needs at least four keys: the first and the last
/// only shape the end tangents, so the track runs from times[1] to times[size - 2].
enum class Interpolation { Step, Linear, KochanekBartels };

template <typename V>
struct Keyframes {
  std::vector<float> times; ///< seconds, strictly increasing
  std::vector<V> values;    ///< one per time
  Interpolation interpolation = Interpolation::Linear;
  /// KochanekBartels only: tension, continuity, bias per key (one per time); empty otherwise.
  std::vector<vec3> tcb;
  [[nodiscard]] bool empty() const { return times.empty(); }
  /// The last time the track changes (non-empty tracks): its last key's, or for
  /// KochanekBartels the last inner key's (the last key only shapes the end tangent).
  [[nodiscard]] float end_time() const {
    return interpolation == Interpolation::KochanekBartels && times.size() >= 2
               ? times[times.size() - 2]
               : times.back();
  }
  friend bool operator==(const Keyframes&, const Keyframes&) = default;
};

/// Keyframed TRS tracks (applied to Transform) and vertex animation (applied to Mesh: each key is
/// a full set of positions, as many as the mesh's vertices; an optional normal track, only beside
/// a vertex track, gives each key's vertex normals, interpolated like positions then normalised).
/// animation_system samples at `time + speed * t`; with `loop`, time wraps to the track's duration.
/// Translation keys are double (world positions far from the origin keep their precision).
/// Visibility switches (BART's `visibility` keys): from each key's time on, the entity and its
/// subtree are shown (1) or hidden (0); before the first key, the first key's state.
struct VisibilityKeys {
  std::vector<float> times;          ///< seconds, strictly increasing
  std::vector<std::uint8_t> visible; ///< 0 or 1, one per time
  [[nodiscard]] bool empty() const { return times.empty(); }
  friend bool operator==(const VisibilityKeys&, const VisibilityKeys&) = default;
};

struct Animation {
  Keyframes<dvec3> translation;
  Keyframes<quat> rotation;
  Keyframes<vec3> scale;
  Keyframes<std::vector<vec3>> vertices;
  Keyframes<std::vector<vec3>> normals;
  VisibilityKeys visibility;
  float time = 0.0f;
  float speed = 1.0f;
  bool loop = true;

  /// The last time any track changes (Keyframes::end_time; 0 when there are none): where a
  /// looping animation wraps.
  [[nodiscard]] float duration() const;
  friend bool operator==(const Animation&, const Animation&) = default;
};

inline float Animation::duration() const {
  float d = 0.0f;
  if (!translation.empty()) d = glm::max(d, translation.end_time());
  if (!rotation.empty()) d = glm::max(d, rotation.end_time());
  if (!scale.empty()) d = glm::max(d, scale.end_time());
  if (!vertices.empty()) d = glm::max(d, vertices.end_time());
  if (!normals.empty()) d = glm::max(d, normals.end_time());
  if (!visibility.empty()) d = glm::max(d, visibility.times.back());
  return d;
}

} // namespace specula
