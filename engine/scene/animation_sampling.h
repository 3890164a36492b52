#pragma once
/// \file
/// Sampling keyframe tracks (Animation, CameraPath) and validating them for loaders.

#include "specula/scene/components/animation.h"
#include "specula/scene/components/camera.h"

#include <cstddef>
#include <string>
#include <vector>

namespace specula {

/// Track value at time t: clamped to the first/last key outside the keys' range; Step holds the
/// previous key; Linear lerps vectors and slerps rotations (shortest arc); KochanekBartels
/// (BART's kbsplpos/kbsplrot, see Interpolation) is clamped to keys 1 and size-2, passes through
/// every key in between, and keeps rotations unit length. Tracks must be non-empty and valid
/// (validate_animation).
[[nodiscard]] vec3 sample(const Keyframes<vec3>& track, float t);
[[nodiscard]] dvec3 sample(const Keyframes<dvec3>& track, float t);
[[nodiscard]] quat sample(const Keyframes<quat>& track, float t);
/// Writes the interpolated vertex set into `out` (resized to the keys' vertex count).
void sample(const Keyframes<std::vector<vec3>>& track, float t, std::vector<vec3>& out);
/// The same for a normal track, each blended normal then normalised (keys need not be unit
/// length; where two keys' normals blend to zero length, the nearer key's normal, normalised).
void sample_normals(const Keyframes<std::vector<vec3>>& track, float t, std::vector<vec3>& out);

/// The time to sample at after advancing by `dt`: time + speed·dt, wrapped into [0, duration]
/// when looping (duration 0: always 0).
[[nodiscard]] float advance_time(float time, float speed, float dt, float duration, bool loop);

/// Camera position and look-at on the path at time t (linear between keys, clamped).
[[nodiscard]] CameraPath::Key sample(const CameraPath& path, float t);
/// Whether visibility keys show their entity at time t (the last key at or before t; the first
/// key before it).
[[nodiscard]] bool visible_at(const VisibilityKeys& keys, float t);

/// Throws specula::Error(context, field, ...) for: times not finite or not strictly increasing,
/// a Kochanek-Bartels track with fewer than 4 keys or without one tcb triple in [-1, 1] per key,
/// tcb on another interpolation, a Kochanek-Bartels vertex track, a values count different from the
/// times count, non-finite values, translations or camera positions outside ±kMaxCoordinate
/// (core/math.h), zero-length rotations, vertex or normal keys whose size differs from
/// `vertex_count` (pass 0 when there is no mesh: any vertex track is then an error), a normal track
/// without a vertex track, Kochanek-Bartels or zero-length or non-finite normals, non-finite speed.
void validate_animation(const Animation& animation, std::size_t vertex_count,
                        const std::string& context, const std::string& field);
void validate_camera_path(const CameraPath& path, const std::string& context,
                          const std::string& field);

} // namespace specula
