#pragma once
/// \file
/// The renderer's template body, included only by backend .cpp files that instantiate it.

#include "specula/core/error.h"
#include "specula/geometry/ray_offset.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/optics.h"
#include "specula/trace/renderer.h"
#include "specula/trace/trace_backend.h"

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <xmmintrin.h>
#include <pmmintrin.h>

#include <algorithm>
#include <atomic>
#include <limits>
#include <numbers>
#include <thread>

namespace specula {
namespace detail {

/// A ray waiting to be traced, with what it carries back and where it comes from: the entity it
/// leaves and why (ray-cache cubes intercept reflection and refraction rays by this).
struct PendingRay {
  Ray ray;
  vec3 weight;
  std::uint32_t depth;
  RayKind kind;
  ecs::Entity from;
};

struct ShadingPoint {
  vec3 position;
  vec3 position_error;   ///< bound on the rounding error of position (ray_offset.h)
  vec3 geometric_normal; ///< facing the incoming ray
  vec3 shading_normal;   ///< facing the same side as geometric_normal
  bool front_face;       ///< the ray hit the side the triangle's winding faces (entering)
};

/// Hit position from barycentrics on the triangle (more accurate than origin + t·d far from the
/// ray origin), normals oriented towards the incoming direction.
inline ShadingPoint shading_point(const Surface& s, const Hit& hit, const vec3& direction,
                                  bool with_error_bound = true) {
  const uvec3 tri = s.mesh->triangles[hit.primitive];
  const float w = 1.0f - hit.uv.x - hit.uv.y;
  const vec3& p0 = s.positions[tri.x];
  const vec3& p1 = s.positions[tri.y];
  const vec3& p2 = s.positions[tri.z];
  const vec3 p_object = w * p0 + hit.uv.x * p1 + hit.uv.y * p2;
  ShadingPoint sp;
  sp.position = vec3(s.world_from_object * vec4(p_object, 1.0f));
  sp.position_error = with_error_bound ? transformed_error(s.world_from_object, p_object,
                                                           barycentric_error(p0, p1, p2, w, hit.uv.x, hit.uv.y))
                                       : vec3(0.0f);
  const vec3 normal = s.world_normal(hit.object_normal);
  sp.front_face = glm::dot(normal, direction) < 0.0f;
  sp.geometric_normal = sp.front_face ? normal : -normal;
  sp.shading_normal = sp.geometric_normal;
  if (s.smooth_normals && !s.mesh->normals.empty()) {
    const auto& n = s.mesh->normals;
    const vec3 n_object = w * n[tri.x] + hit.uv.x * n[tri.y] + hit.uv.y * n[tri.z];
    vec3 ns = s.world_normal_from_object * n_object;
    const float len = glm::length(ns);
    if (len > 0.0f && std::isfinite(len)) {
      ns /= len;
      sp.shading_normal = glm::dot(ns, sp.geometric_normal) < 0.0f ? -ns : ns;
    }
  }
  return sp;
}

/// How a Whitted hit continues: mirror reflection with the material's reflectivity plus the
/// Fresnel-reflected part of its transmission; refraction with the rest (none on total internal
/// reflection). Directions are unit and leave on the correct side of the geometric surface even
/// where the interpolated shading normal disagrees with it.
struct SpecularSplit {
  float reflect_weight = 0.0f;
  vec3 reflect_direction{0.0f};
  float refract_weight = 0.0f;
  vec3 refract_direction{0.0f};
};

inline SpecularSplit split_specular(const Material& m, const ShadingPoint& sp, const vec3& d) {
  SpecularSplit split;
  split.reflect_weight = m.reflectivity;
  if (m.transmission > 0.0f) {
    const float eta = sp.front_face ? 1.0f / m.ior : m.ior;
    std::optional<vec3> t = refract_direction(d, sp.shading_normal, eta);
    float cos_i = -glm::dot(d, sp.shading_normal);
    if (t && glm::dot(*t, sp.geometric_normal) >= 0.0f) {
      t = refract_direction(d, sp.geometric_normal, eta); // the shading normal bent it out
      cos_i = -glm::dot(d, sp.geometric_normal);
    }
    if (t) {
      const float f = fresnel_dielectric(cos_i, eta);
      split.reflect_weight += m.transmission * f;
      split.refract_weight = m.transmission * (1.0f - f);
      split.refract_direction = *t;
    } else {
      split.reflect_weight += m.transmission; // total internal reflection
    }
  }
  if (split.reflect_weight > 0.0f) {
    vec3 r = reflect_direction(d, sp.shading_normal);
    if (glm::dot(r, sp.geometric_normal) <= 0.0f) r = reflect_direction(d, sp.geometric_normal);
    split.reflect_direction = glm::normalize(r);
  }
  return split;
}

inline float max_component(const vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

/// Local shading at a hit (emission and the diffuse term from every light; shadow rays in
/// Whitted mode), then, in Whitted mode and below the depth limit, the reflection and
/// refraction rays it spawns, pushed on `stack` with their weights.
template <typename Backend>
vec3 shade_hit(const Backend& backend, const PendingRay& pending, const Hit& hit,
               std::span<const SceneLight> lights, const TraceSettings& settings, RayCounts& counts,
               PendingRay* stack, std::size_t& top, std::size_t capacity) {
  constexpr float kInvPi = std::numbers::inv_pi_v<float>;
  const bool whitted = settings.mode == TraceMode::Whitted;
  const Surface& surface = backend.surfaces()[hit.surface];
  const Material& m = surface.material;
  // Only Whitted spawns rays, and only spawned rays need the error bound.
  const ShadingPoint sp = shading_point(surface, hit, pending.ray.direction, whitted);
  vec3 radiance = pending.weight * m.emission;

  // Local (diffuse) term. Cast mode shades every surface with its base colour and no shadows.
  const float diffuse = whitted ? std::max(0.0f, 1.0f - m.reflectivity - m.transmission) : 1.0f;
  if (diffuse > 0.0f && !lights.empty()) {
    const vec3 albedo_weight = pending.weight * m.base_color * (diffuse * kInvPi);
    const vec3 shadow_origin =
        whitted ? offset_ray_origin(sp.position, sp.position_error, sp.geometric_normal) : sp.position;
    for (const SceneLight& light : lights) {
      const LightSample ls = sample_light(light, sp.position);
      if (glm::dot(ls.to_light, sp.geometric_normal) <= 0.0f) continue; // behind the surface
      const float cos_theta = glm::dot(ls.to_light, sp.shading_normal);
      if (cos_theta <= 0.0f || max_component(ls.irradiance) <= 0.0f) continue;
      if (whitted) {
        Ray shadow;
        shadow.origin = shadow_origin;
        shadow.direction = ls.to_light;
        // Stop just short of the light: a light placed on a surface must not shadow itself.
        shadow.tfar = std::isinf(ls.distance)
                          ? ls.distance
                          : glm::length(light.position - shadow_origin) * (1.0f - 1e-5f);
        ++counts[RayKind::Shadow];
        if (backend.occluded(shadow)) continue;
      }
      radiance += albedo_weight * ls.irradiance * cos_theta;
    }
  }
  if (!whitted || pending.depth >= settings.max_depth) return radiance;

  const SpecularSplit split = split_specular(m, sp, pending.ray.direction);
  const auto push = [&](const vec3& origin, const vec3& direction, float w, RayKind kind) {
    const vec3 weight = pending.weight * w;
    if (max_component(weight) < settings.min_weight || top == capacity) return;
    PendingRay& next = stack[top++];
    next.ray = Ray{origin, 0.0f, direction, std::numeric_limits<float>::infinity()};
    next.weight = weight;
    next.depth = pending.depth + 1;
    next.kind = kind;
    next.from = surface.entity;
  };
  if (split.reflect_weight > 0.0f)
    push(offset_ray_origin(sp.position, sp.position_error, sp.geometric_normal),
         split.reflect_direction, split.reflect_weight, RayKind::Reflection);
  if (split.refract_weight > 0.0f)
    push(offset_ray_origin(sp.position, sp.position_error, -sp.geometric_normal),
         split.refract_direction, split.refract_weight, RayKind::Refraction);
  return radiance;
}

/// Radiance along one primary ray whose first hit is already known: local shading (cast) or the
/// full Whitted tree (shadow rays to every light, mirror reflection, refraction with Fresnel and
/// total internal reflection), walked depth-first with an explicit stack. Depth-first keeps at
/// most one pending sibling per level, so max_depth + 2 entries suffice (max_depth ≤ 32).
template <typename Backend>
vec3 shade(const Backend& backend, const Ray& primary, const Hit& primary_hit,
           std::span<const SceneLight> lights, const TraceSettings& settings, RayCounts& counts) {
  if (!primary_hit.hit()) return settings.background;
  constexpr std::size_t kCapacity = 40;
  PendingRay stack[kCapacity]; // left uninitialised: PendingRay is trivially constructible
  std::size_t top = 0;
  const PendingRay first{primary, vec3(1.0f), 0, RayKind::Primary, ecs::null_entity};
  vec3 radiance = shade_hit(backend, first, primary_hit, lights, settings, counts, stack, top, kCapacity);
  while (top > 0) {
    const PendingRay pending = stack[--top];
    Hit hit;
    backend.intersect(pending.ray, hit);
    ++counts[pending.kind];
    if (!hit.hit()) {
      radiance += pending.weight * settings.background;
      continue;
    }
    radiance += shade_hit(backend, pending, hit, lights, settings, counts, stack, top, kCapacity);
  }
  return radiance;
}

/// One worker's scratch for a tile: the hits of its primary rays in the tile's trace order
/// (PacketTile; the same walk maps them back to pixels).
struct TileBatch {
  PacketTile tile;
  std::vector<Hit> hits;

  /// The primary-ray stage of a tile: the backend generates the camera rays into its coherent
  /// packets and returns the closest hits.
  template <typename Backend>
  void trace_primary(const Backend& backend, const CameraRays& camera, std::uint32_t x0, std::uint32_t y0,
                     std::uint32_t x1, std::uint32_t y1) {
    tile = PacketTile::for_width(x0, y0, x1, y1, backend.packet_width());
    hits.resize(tile.pixel_count());
    backend.intersect_camera(camera, tile, hits);
  }
};

/// Runs f(batch, x0, y0, x1, y1) for every tile of a width × height image, tiles handed out
/// dynamically to `threads` workers (0: all), each worker with its own TileBatch. TBB's default
/// partitioner splits the tile range adaptively and idle workers steal halves of busy ones'
/// ranges, so neighbouring tiles usually run on one worker back to back (cache-friendly) while
/// the load still balances; one task per tile measured slower here.
template <typename F>
void for_each_tile(std::uint32_t width, std::uint32_t height, std::uint32_t tile, std::uint32_t threads, F&& f) {
  tile = std::max(1u, tile);
  const std::uint32_t tiles_x = (width + tile - 1) / tile;
  const std::uint32_t tiles_y = (height + tile - 1) / tile;
  const int workers = threads > 0 ? int(threads) : int(std::max(1u, std::thread::hardware_concurrency()));
  tbb::task_arena arena(workers);
  tbb::enumerable_thread_specific<TileBatch> batches; // one scratch per worker, reused across tiles
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, tiles_x * tiles_y, 1),
                      [&](const tbb::blocked_range<std::uint32_t>& range) {
                        // Denormals slow Embree down and make it warn: flush them while tracing,
                        // and give the thread (possibly the caller's own) its mode back after.
                        const unsigned int saved_csr = _mm_getcsr();
                        _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                        _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                        TileBatch& batch = batches.local();
                        for (std::uint32_t t = range.begin(); t != range.end(); ++t) {
                          const std::uint32_t x0 = (t % tiles_x) * tile;
                          const std::uint32_t y0 = (t / tiles_x) * tile;
                          f(batch, x0, y0, std::min(x0 + tile, width), std::min(y0 + tile, height));
                        }
                        _mm_setcsr(saved_csr);
                      });
  });
}

} // namespace detail

/// The primary-ray stage alone over a whole frame (what render_frame runs before shading);
/// returns a checksum of the hits so the work cannot be optimised away. For benchmarks.
template <typename Backend>
std::uint64_t trace_primary_frame(const Backend& backend, const Camera& camera, std::uint32_t width,
                                  std::uint32_t height, const TraceSettings& settings) {
  const CameraRays camera_rays(camera, width, height);
  std::atomic<std::uint64_t> checksum{0};
  detail::for_each_tile(width, height, settings.tile_size, settings.threads,
                        [&](detail::TileBatch& batch, std::uint32_t x0, std::uint32_t y0, std::uint32_t x1, std::uint32_t y1) {
                          batch.trace_primary(backend, camera_rays, x0, y0, x1, y1);
                          std::uint64_t local = 0;
                          for (const Hit& h : batch.hits) local += h.surface + h.primitive;
                          checksum += local;
                        });
  return checksum.load();
}

template <typename Backend>
FrameStats render_frame(const Backend& backend, const Camera& camera,
                        std::span<const SceneLight> lights, const TraceSettings& settings,
                        Framebuffer& out) {
  static_assert(TraceBackend<Backend>);
  if (settings.mode == TraceMode::Path || settings.mode == TraceMode::Shadow)
    throw UnavailableError(std::string("mode '") + trace_mode_name(settings.mode) +
                           "' is not available yet");
  const std::uint32_t width = out.width();
  const CameraRays camera_rays(camera, width, out.height());
  const std::span<vec3> pixels = out.pixels();
  tbb::combinable<RayCounts> counts;
  detail::for_each_tile(width, out.height(), settings.tile_size, settings.threads,
                        [&](detail::TileBatch& batch, std::uint32_t x0, std::uint32_t y0, std::uint32_t x1, std::uint32_t y1) {
                          batch.trace_primary(backend, camera_rays, x0, y0, x1, y1);
                          RayCounts& local = counts.local();
                          local[RayKind::Primary] += batch.hits.size();
                          std::size_t i = 0;
                          batch.tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
                            // The ray is regenerated for shading: cheaper than keeping every
                            // tile's rays in memory between the two stages.
                            pixels[std::size_t(y) * width + x] = detail::shade(
                                backend, camera_rays.ray(x, y), batch.hits[i++], lights, settings, local);
                          });
                        });
  FrameStats stats;
  counts.combine_each([&](const RayCounts& c) { stats.rays += c; });
  return stats;
}

} // namespace specula
