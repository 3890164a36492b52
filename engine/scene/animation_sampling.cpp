#include "specula/scene/animation_sampling.h"

#include "specula/core/error.h"

#include <algorithm>
#include <cmath>

namespace specula {
namespace {

/// Index i of the segment [times[i], times[i+1]] holding t and the blend factor within it.
/// Requires times.size() >= 2 and times.front() < t < times.back().
std::pair<std::size_t, float> locate(const std::vector<float>& times, float t) {
  const auto it = std::upper_bound(times.begin(), times.end(), t);
  const auto i = static_cast<std::size_t>(std::distance(times.begin(), it)) - 1;
  const float span = times[i + 1] - times[i];
  return {i, span > 0.0f ? (t - times[i]) / span : 0.0f};
}

template <typename V, typename Mix>
V sample_track(const Keyframes<V>& track, float t, Mix mix) {
  if (t <= track.times.front()) return track.values.front();
  if (t >= track.times.back()) return track.values.back();
  const auto [i, f] = locate(track.times, t);
  if (track.interpolation == Interpolation::Step) return track.values[i];
  return mix(track.values[i], track.values[i + 1], f);
}

template <typename V>
void check_times(const Keyframes<V>& track, const std::string& context, const std::string& field) {
  if (track.times.size() != track.values.size())
    throw Error(context, field, std::to_string(track.times.size()) + " key times but " +
                                    std::to_string(track.values.size()) + " values");
  for (std::size_t i = 0; i < track.times.size(); ++i) {
    if (!std::isfinite(track.times[i]))
      throw Error(context, field + ".times[" + std::to_string(i) + "]", "time is not finite");
    if (i > 0 && !(track.times[i] > track.times[i - 1]))
      throw Error(context, field + ".times[" + std::to_string(i) + "]",
                  "key times must be strictly increasing");
  }
}

} // namespace

vec3 sample(const Keyframes<vec3>& track, float t) {
  return sample_track(track, t, [](const vec3& a, const vec3& b, float f) { return glm::mix(a, b, f); });
}

dvec3 sample(const Keyframes<dvec3>& track, float t) {
  return sample_track(track, t, [](const dvec3& a, const dvec3& b, float f) {
    return glm::mix(a, b, double(f));
  });
}

quat sample(const Keyframes<quat>& track, float t) {
  return sample_track(track, t, [](const quat& a, const quat& b, float f) {
    return glm::normalize(glm::slerp(a, b, f));
  });
}

void sample(const Keyframes<std::vector<vec3>>& track, float t, std::vector<vec3>& out) {
  const std::vector<vec3>* a = &track.values.front();
  const std::vector<vec3>* b = a;
  float f = 0.0f;
  if (t >= track.times.back()) {
    a = b = &track.values.back();
  } else if (t > track.times.front()) {
    const auto [i, blend] = locate(track.times, t);
    a = &track.values[i];
    b = track.interpolation == Interpolation::Step ? a : &track.values[i + 1];
    f = blend;
  }
  out.resize(a->size());
  for (std::size_t v = 0; v < a->size(); ++v) out[v] = glm::mix((*a)[v], (*b)[v], f);
}

float advance_time(float time, float speed, float dt, float duration, bool loop) {
  float t = time + speed * dt;
  if (!loop) return t;
  if (!(duration > 0.0f)) return 0.0f;
  t = std::fmod(t, duration);
  return t < 0.0f ? t + duration : t;
}

CameraPath::Key sample(const CameraPath& path, float t) {
  const auto& keys = path.keys;
  if (t <= keys.front().time) return keys.front();
  if (t >= keys.back().time) return keys.back();
  const auto it = std::upper_bound(keys.begin(), keys.end(), t,
                                   [](float v, const CameraPath::Key& k) { return v < k.time; });
  const auto i = static_cast<std::size_t>(std::distance(keys.begin(), it)) - 1;
  const float f = (t - keys[i].time) / (keys[i + 1].time - keys[i].time);
  return CameraPath::Key{t, glm::mix(keys[i].position, keys[i + 1].position, double(f)),
                         glm::mix(keys[i].look_at, keys[i + 1].look_at, double(f))};
}

void validate_animation(const Animation& a, std::size_t vertex_count, const std::string& context,
                        const std::string& field) {
  check_times(a.translation, context, field + ".translation");
  check_times(a.rotation, context, field + ".rotation");
  check_times(a.scale, context, field + ".scale");
  check_times(a.vertices, context, field + ".vertices");
  for (std::size_t i = 0; i < a.translation.values.size(); ++i)
    if (!is_finite(a.translation.values[i]) || !in_range(a.translation.values[i]))
      throw Error(context, field + ".translation.values[" + std::to_string(i) + "]",
                  std::string("translation is not finite or outside ") + kCoordinateRangeText);
  for (std::size_t i = 0; i < a.rotation.values.size(); ++i) {
    const quat& q = a.rotation.values[i];
    if (!is_finite(q) || glm::length(q) < 1e-6f)
      throw Error(context, field + ".rotation.values[" + std::to_string(i) + "]",
                  "rotation is not a finite, non-zero quaternion");
  }
  for (std::size_t i = 0; i < a.scale.values.size(); ++i)
    if (!is_finite(a.scale.values[i]))
      throw Error(context, field + ".scale.values[" + std::to_string(i) + "]", "value is not finite");
  for (std::size_t k = 0; k < a.vertices.values.size(); ++k) {
    const auto& key = a.vertices.values[k];
    if (key.size() != vertex_count)
      throw Error(context, field + ".vertices.values[" + std::to_string(k) + "]",
                  "key has " + std::to_string(key.size()) + " vertices but the mesh has " +
                      std::to_string(vertex_count));
    for (const vec3& p : key)
      if (!is_finite(p) || !in_range(p))
        throw Error(context, field + ".vertices.values[" + std::to_string(k) + "]",
                    std::string("vertex position is not finite or outside ") +
                        kCoordinateRangeText);
  }
  if (!std::isfinite(a.speed) || !std::isfinite(a.time))
    throw Error(context, field, "speed and time must be finite");
}

void validate_camera_path(const CameraPath& path, const std::string& context,
                          const std::string& field) {
  if (path.keys.empty()) throw Error(context, field, "a camera path needs at least one key");
  for (std::size_t i = 0; i < path.keys.size(); ++i) {
    const auto& k = path.keys[i];
    const std::string at = field + ".keys[" + std::to_string(i) + "]";
    if (!std::isfinite(k.time) || !is_finite(k.position) || !is_finite(k.look_at))
      throw Error(context, at, "time, position and look_at must be finite");
    if (!in_range(k.position) || !in_range(k.look_at))
      throw Error(context, at,
                  std::string("position or look_at is outside ") + kCoordinateRangeText);
    if (i > 0 && !(k.time > path.keys[i - 1].time))
      throw Error(context, at, "key times must be strictly increasing");
    if (glm::length(k.position - k.look_at) <= 0.0f)
      throw Error(context, at, "position and look_at must differ");
  }
}

} // namespace specula
