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

/// The tangent weights of Kochanek–Bartels at the two ends of segment [i, i+1] (keys i-1 .. i+2
/// exist), time-adjusted as BART's kbsplpos/kbsplrot do (Eberly's formulation): the outgoing
/// tangent at key i is out_next·(P[i+1]-P[i]) + out_prev·(P[i]-P[i-1]) and the incoming one at
/// key i+1 is in_next·(P[i+2]-P[i+1]) + in_prev·(P[i+1]-P[i]).
struct KbWeights {
  double out_prev, out_next, in_prev, in_next;
};

template <typename V>
KbWeights kb_weights(const Keyframes<V>& track, std::size_t i) {
  const auto& k = track.times;
  const vec3 a = track.tcb[i];     // tension, continuity, bias at key i
  const vec3 b = track.tcb[i + 1]; // ... at key i+1
  // Non-uniform key spacing: scale each tangent to the segment's length in time.
  const double adj0 = 2.0 * (double(k[i + 1]) - k[i]) / (double(k[i + 1]) - k[i - 1]);
  const double adj1 = 2.0 * (double(k[i + 1]) - k[i]) / (double(k[i + 2]) - k[i]);
  return KbWeights{0.5 * adj0 * (1.0 - a.x) * (1.0 + a.y) * (1.0 + a.z),
                   0.5 * adj0 * (1.0 - a.x) * (1.0 - a.y) * (1.0 - a.z),
                   0.5 * adj1 * (1.0 - b.x) * (1.0 - b.y) * (1.0 + b.z),
                   0.5 * adj1 * (1.0 - b.x) * (1.0 + b.y) * (1.0 - b.z)};
}

/// Kochanek–Bartels on vectors: the cubic Hermite segment between keys i and i+1 at blend u.
template <typename V>
V kb_vector(const Keyframes<V>& track, std::size_t i, double u) {
  using D = glm::dvec3;
  const D p0(track.values[i - 1]), p1(track.values[i]), p2(track.values[i + 1]),
      p3(track.values[i + 2]);
  const KbWeights w = kb_weights(track, i);
  const D dp = p2 - p1;
  const D t_out = w.out_next * dp + w.out_prev * (p1 - p0);
  const D t_in = w.in_next * (p3 - p2) + w.in_prev * dp;
  const D c2 = 3.0 * dp - 2.0 * t_out - t_in;
  const D c3 = -2.0 * dp + t_out + t_in;
  return V(p1 + u * (t_out + u * (c2 + u * c3)));
}

/// log of a unit quaternion as a pure vector (angle/2 times the axis).
dvec3 quat_log(const glm::dquat& q) {
  const dvec3 v(q.x, q.y, q.z);
  const double s = glm::length(v);
  if (s < 1e-12) return v;
  return v * (std::atan2(s, q.w) / s);
}

glm::dquat quat_exp(const dvec3& v) {
  const double a = glm::length(v);
  const double f = a < 1e-12 ? 1.0 : std::sin(a) / a;
  return glm::dquat(std::cos(a), v.x * f, v.y * f, v.z * f);
}

/// Kochanek–Bartels on rotations as BART's kbsplrot: the tangents above taken on
/// log(q[j]^-1 q[j+1]), turned into the inner control points a, b of squad (Shoemake), and
/// squad(u) = slerp(slerp(q1, q2, u), slerp(a, b, u), 2u(1-u)). Consecutive keys are first put
/// on the same hemisphere, so every segment takes the shorter arc.
quat kb_rotation(const Keyframes<quat>& track, std::size_t i, double u) {
  glm::dquat q[4];
  for (int j = 0; j < 4; ++j) q[j] = glm::normalize(glm::dquat(track.values[i - 1 + j]));
  for (int j = 1; j < 4; ++j)
    if (glm::dot(q[j - 1], q[j]) < 0.0) q[j] = -q[j];
  const KbWeights w = kb_weights(track, i);
  const dvec3 log_prev = quat_log(glm::inverse(q[0]) * q[1]);
  const dvec3 log_dq = quat_log(glm::inverse(q[1]) * q[2]);
  const dvec3 log_next = quat_log(glm::inverse(q[2]) * q[3]);
  const dvec3 t_out = w.out_next * log_dq + w.out_prev * log_prev;
  const dvec3 t_in = w.in_next * log_next + w.in_prev * log_dq;
  const glm::dquat a = q[1] * quat_exp(0.5 * (t_out - log_dq));
  const glm::dquat b = q[2] * quat_exp(0.5 * (log_dq - t_in));
  const glm::dquat outer = glm::slerp(q[1], q[2], u);
  const glm::dquat inner = glm::slerp(a, b, u);
  return quat(glm::normalize(glm::slerp(outer, inner, 2.0 * u * (1.0 - u))));
}

template <typename V, typename Mix, typename Kb>
V sample_track(const Keyframes<V>& track, float t, Mix mix, Kb kb) {
  if (track.interpolation == Interpolation::KochanekBartels) {
    // As BART: the first and last keys only shape the end tangents; clamp to the inner keys.
    const std::size_t n = track.times.size();
    if (t <= track.times[1]) return track.values[1];
    if (t >= track.times[n - 2]) return track.values[n - 2];
    const auto [i, f] = locate(track.times, t);
    return kb(track, i, double(f));
  }
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
  if (track.interpolation == Interpolation::KochanekBartels) {
    if (track.times.size() < 4)
      throw Error(context, field,
                  "Kochanek-Bartels interpolation needs at least 4 keys (the first and last only "
                  "shape the end tangents), got " + std::to_string(track.times.size()));
    if (track.tcb.size() != track.times.size())
      throw Error(context, field + ".tcb",
                  std::to_string(track.times.size()) + " key times but " +
                      std::to_string(track.tcb.size()) + " tension/continuity/bias triples");
    // Kochanek and Bartels define the three on [-1, 1]; beyond it tangents can overflow.
    for (std::size_t i = 0; i < track.tcb.size(); ++i)
      if (!is_finite(track.tcb[i]) || glm::any(glm::greaterThan(glm::abs(track.tcb[i]), vec3(1.0f))))
        throw Error(context, field + ".tcb[" + std::to_string(i) + "]",
                    "tension, continuity and bias must be in [-1, 1]");
  } else if (!track.tcb.empty()) {
    throw Error(context, field + ".tcb",
                "tension/continuity/bias only apply to Kochanek-Bartels interpolation");
  }
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
  return sample_track(
      track, t, [](const vec3& a, const vec3& b, float f) { return glm::mix(a, b, f); },
      kb_vector<vec3>);
}

dvec3 sample(const Keyframes<dvec3>& track, float t) {
  return sample_track(
      track, t, [](const dvec3& a, const dvec3& b, float f) { return glm::mix(a, b, double(f)); },
      kb_vector<dvec3>);
}

quat sample(const Keyframes<quat>& track, float t) {
  return sample_track(
      track, t,
      [](const quat& a, const quat& b, float f) { return glm::normalize(glm::slerp(a, b, f)); },
      kb_rotation);
}

namespace {

/// The two vertex-set keys around time t and the blend between them (a == b outside the keys
/// and for Step).
struct VertexKeys {
  const std::vector<vec3>* a;
  const std::vector<vec3>* b;
  float f;
};

VertexKeys vertex_keys(const Keyframes<std::vector<vec3>>& track, float t) {
  VertexKeys k{&track.values.front(), &track.values.front(), 0.0f};
  if (t >= track.times.back()) {
    k.a = k.b = &track.values.back();
  } else if (t > track.times.front()) {
    const auto [i, blend] = locate(track.times, t);
    k.a = &track.values[i];
    k.b = track.interpolation == Interpolation::Step ? k.a : &track.values[i + 1];
    k.f = blend;
  }
  return k;
}

} // namespace

void sample(const Keyframes<std::vector<vec3>>& track, float t, std::vector<vec3>& out) {
  const auto [a, b, f] = vertex_keys(track, t);
  out.resize(a->size());
  for (std::size_t v = 0; v < a->size(); ++v) out[v] = glm::mix((*a)[v], (*b)[v], f);
}

void sample_normals(const Keyframes<std::vector<vec3>>& track, float t, std::vector<vec3>& out) {
  const auto [a, b, f] = vertex_keys(track, t);
  out.resize(a->size());
  for (std::size_t v = 0; v < a->size(); ++v) {
    const vec3 n = glm::mix((*a)[v], (*b)[v], f);
    // Keys of opposite normals may blend to zero between them: the nearer key's normal then.
    const float len = glm::length(n);
    out[v] = len > 1e-6f ? n / len : glm::normalize(f < 0.5f ? (*a)[v] : (*b)[v]);
  }
}

float advance_time(float time, float speed, float dt, float duration, bool loop) {
  float t = time + speed * dt;
  if (!loop) return t;
  if (!(duration > 0.0f)) return 0.0f;
  t = std::fmod(t, duration);
  return t < 0.0f ? t + duration : t;
}

bool visible_at(const VisibilityKeys& keys, float t) {
  const auto it = std::upper_bound(keys.times.begin(), keys.times.end(), t);
  const std::size_t i = it == keys.times.begin() ? 0 : std::size_t(it - keys.times.begin()) - 1;
  return keys.visible[i] != 0;
}

CameraPath::Key sample(const CameraPath& path, float t) {
  const auto& keys = path.keys;
  if (t <= keys.front().time) return keys.front();
  if (t >= keys.back().time) return keys.back();
  const auto it = std::upper_bound(keys.begin(), keys.end(), t,
                                   [](float v, const CameraPath::Key& k) { return v < k.time; });
  const auto i = static_cast<std::size_t>(std::distance(keys.begin(), it)) - 1;
  const float f = (t - keys[i].time) / (keys[i + 1].time - keys[i].time);
  // The up vector turns from key to key (normalised linear blend: a roll of under 180° between
  // two keys; exactly opposite ups keep the earlier one).
  const vec3 up = glm::mix(glm::normalize(keys[i].up), glm::normalize(keys[i + 1].up), f);
  return CameraPath::Key{t, glm::mix(keys[i].position, keys[i + 1].position, double(f)),
                         glm::mix(keys[i].look_at, keys[i + 1].look_at, double(f)),
                         glm::length(up) > 1e-6f ? glm::normalize(up) : keys[i].up};
}

void validate_animation(const Animation& a, std::size_t vertex_count, const std::string& context,
                        const std::string& field) {
  check_times(a.translation, context, field + ".translation");
  check_times(a.rotation, context, field + ".rotation");
  check_times(a.scale, context, field + ".scale");
  check_times(a.vertices, context, field + ".vertices");
  if (a.visibility.times.size() != a.visibility.visible.size())
    throw Error(context, field + ".visibility",
                std::to_string(a.visibility.times.size()) + " key times but " +
                    std::to_string(a.visibility.visible.size()) + " values");
  for (std::size_t i = 0; i < a.visibility.times.size(); ++i) {
    const std::string at = field + ".visibility.times[" + std::to_string(i) + "]";
    if (!std::isfinite(a.visibility.times[i])) throw Error(context, at, "time is not finite");
    if (i > 0 && !(a.visibility.times[i] > a.visibility.times[i - 1]))
      throw Error(context, at, "key times must be strictly increasing");
    if (a.visibility.visible[i] > 1)
      throw Error(context, field + ".visibility.values[" + std::to_string(i) + "]",
                  "a visibility key is 0 (hidden) or 1 (shown)");
  }
  check_times(a.normals, context, field + ".normals");
  if (a.vertices.interpolation == Interpolation::KochanekBartels)
    throw Error(context, field + ".vertices",
                "vertex tracks interpolate linearly or by step, not Kochanek-Bartels");
  if (a.normals.interpolation == Interpolation::KochanekBartels)
    throw Error(context, field + ".normals",
                "normal tracks interpolate linearly or by step, not Kochanek-Bartels");
  if (!a.normals.empty() && a.vertices.empty())
    throw Error(context, field + ".normals",
                "a normal track needs a vertex track beside it (the normals of what positions?)");
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
  for (std::size_t k = 0; k < a.normals.values.size(); ++k) {
    const auto& key = a.normals.values[k];
    const std::string at = field + ".normals.values[" + std::to_string(k) + "]";
    if (key.size() != vertex_count)
      throw Error(context, at,
                  "key has " + std::to_string(key.size()) + " normals but the mesh has " +
                      std::to_string(vertex_count) + " vertices");
    for (const vec3& n : key)
      if (!is_finite(n) || !(glm::length(n) > 1e-6f))
        throw Error(context, at, "vertex normal is not finite or has zero length");
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
    if (!is_finite(k.up) || !(glm::length(k.up) > 0.0f))
      throw Error(context, at, "up must be finite and not zero");
    const vec3 forward(glm::normalize(k.look_at - k.position));
    if (glm::length(glm::cross(forward, glm::normalize(k.up))) <= 1e-4f)
      throw Error(context, at, "up is parallel to the view direction, so the camera roll is undefined");
  }
}

} // namespace specula
