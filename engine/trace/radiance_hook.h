#pragma once
/// \file
/// The leaving-radiance hook: where the radiance that a secondary ray brings back to the object it
/// leaves is delivered, as its own value. A ray-cache cube (Ruff, Clua, Fernandes 2013) stores
/// exactly this — "the colour of rays that leave the object", indexed by direction — so the cache
/// work plugs in here; until then no hook is installed and integrators skip the bookkeeping.
///
/// The radiance of a leaving ray is everything it brings back: the local shading where it lands
/// plus, weighted, the radiance of the rays spawned there — nested leaving rays included (a sphere
/// seen in a sphere: the inner ray is delivered to the inner sphere, and its contribution is part
/// of the outer ray's radiance delivered to the outer one). A pixel is its primary hit's local
/// shading plus the sum over the rays leaving that hit of weight × radiance.
///
/// In path mode a leaving ray's radiance is a one-sample Monte Carlo estimate of what its first
/// hit scatters back along it (the rest of its path after that hit: next-event estimates and
/// bounces, divided by its throughput; the emission at the hit itself is left out, since the
/// traced ray gives it exactly): a hook that caches it averages the samples, and path mode asks
/// it after tracing the leaving ray, with that hit (RadianceHook::begin_frame says which mode
/// the frame is).

#include "specula/core/math.h"
#include "specula/ecs/entity.h"
#include "specula/trace/stats.h"
#include "specula/trace/trace_mode.h"

#include <cstdint>
#include <span>

namespace specula {

/// How a leaving ray was served, when a hook answered a lookup for it (RadianceHook::lookup).
enum class CacheAnswer : std::uint8_t {
  Trace,      ///< traced (no cached value, or the cached value was not accepted)
  Use,        ///< the cached radiance was used; the ray was not traced
  UseIfClear, ///< use it if nothing lies within clear_distance (an occlusion ray confirms)
  Verify,     ///< the cached radiance would be used, but the ray is traced to measure its error
  /// Path mode: the cached radiance is used for the sample and the ray is traced anyway, for the
  /// cache alone (its path's contributions go to its leaving record, not to the image): a probe
  /// keeps gathering fresh samples while every pixel reads its mean.
  Refresh,
};

/// A ray about to leave an object, asked about before it is traced.
struct LeavingQuery {
  std::uint32_t instance; ///< the scene-layer instance slot it leaves
  std::uint32_t pixel;
  std::uint32_t depth;
  vec3 origin;
  vec3 direction; ///< unit
  std::uint32_t sample = 0; ///< path mode: the sample's index in the pixel's sequence
  /// Path mode asks after tracing the ray: the entity index of its first hit (kNoInstance in
  /// Whitted frames, which ask before) and the distance to it.
  std::uint32_t hit_entity = 0xffffffffu;
  float hit_t = 0.0f;
};

struct CachedRadiance {
  CacheAnswer answer = CacheAnswer::Trace;
  vec3 radiance{0.0f};
  float clear_distance = 0.0f;    ///< UseIfClear: the length the occlusion ray checks
  std::uint32_t seen = 0;         ///< the entity mask of what the cached value saw
};

/// Bit of an entity in a `seen` mask: a 32-bit Bloom-style summary of the entities a ray's
/// subtree hit (entity index modulo 32).
[[nodiscard]] inline std::uint32_t entity_bit(std::uint32_t entity_index) {
  return 1u << (entity_index & 31u);
}

struct LeavingRadiance {
  ecs::Entity from;       ///< the entity the ray leaves
  std::uint32_t instance; ///< its scene-layer instance slot
  RayKind kind;           ///< Reflection or Refraction
  /// The ray goes away from the object (a reflection off its outside, a refraction out of it),
  /// rather than into or inside it: the rays a ray-cache cube caches.
  bool exits;
  CacheAnswer answer;     ///< how it was served (Trace when no lookup was made)
  std::uint32_t depth;    ///< 1 for rays leaving a primary hit
  std::uint32_t pixel;    ///< y · width + x of the pixel it serves
  std::uint32_t sample;   ///< path mode: the sample's index in the pixel's sequence (else 0)
  vec3 origin;            ///< world space
  vec3 direction;         ///< unit, world space
  vec3 weight;     ///< relative to the ray it was spawned by (its share of that ray's radiance)
  vec3 throughput; ///< relative to the pixel (product of weights along the path)
  vec3 radiance;   ///< what the ray brought back (path mode: without its first hit's emission)
  /// Path mode: the emission its first hit gave it, per unit of throughput (radiance + emitted
  /// is all the light that arrived along it); zero for a served ray.
  vec3 emitted{0.0f};
  vec3 cached;     ///< Verify: the cached value the hook offered
  float hit_t;     ///< distance to its first hit (+inf: it left the scene)
  std::uint32_t hit_entity; ///< entity index of its first hit (kNoInstance: none)
  std::uint32_t seen;       ///< entity_bit of every entity its subtree hit
  std::uint32_t rays;       ///< rays traced for it: itself, its shadow rays and its subtree's
};

class RadianceHook {
public:
  virtual ~RadianceHook() = default;
  /// Called by render_frame before the first tile, with the image size and the integrator
  /// (Whitted delivers exact radiance, Path one-sample estimates; Cast and Shadow deliver none).
  virtual void begin_frame(std::uint32_t /*width*/, std::uint32_t /*height*/,
                           TraceMode /*mode*/) {}
  /// Whether the integrators should ask lookup() about leaving rays this frame (read once per
  /// frame, after begin_frame).
  [[nodiscard]] virtual bool wants_lookups() const { return false; }
  /// Whether the integrators should deliver leaving rays this frame (read once per frame, after
  /// begin_frame): path mode's records follow every path's contributions and Whitted's are built
  /// for every node of the ray tree, so a hook with nothing to store says no.
  [[nodiscard]] virtual bool wants_leaving() const { return true; }
  /// Answers, for each ray about to leave an object (only rays that exit), whether a cached
  /// value replaces tracing it (path mode: tracing the rest of its path after its first hit,
  /// given in the query). Called from worker threads, several tiles at once; must read
  /// only what was there at frame start (writes wait for end_frame), so frames are
  /// deterministic.
  virtual void lookup(std::span<const LeavingQuery> queries,
                      std::span<CachedRadiance> answers) const {
    for (CachedRadiance& a : answers) a = CachedRadiance{};
    (void)queries;
  }
  /// Path mode: the light a diffuse surface of `instance` with unit normal n receives, from its
  /// cache's record of what arrives at the object from every direction (a probe of the incoming
  /// radiance): (1/π)∫ L(s) max(0, n·s) ds, so the diffuse lobe reflects albedo × that. False
  /// when the hook has no such probe for the instance (the integrator samples the lobe as
  /// usual). The probe holds every light that rays reach (emitters included, delta lights not):
  /// a vertex lit this way takes no area-light sample for its diffuse lobe and does not continue
  /// it. Called from worker threads; reads only what was there at frame start.
  [[nodiscard]] virtual bool irradiance(std::uint32_t /*instance*/, const vec3& /*n*/,
                                        vec3& /*out*/) const {
    return false;
  }
  /// Receives one tile's leaving rays once the tile's last wave is done, in a deterministic order
  /// (wave by wave, then trace order). Called from worker threads, several tiles at once:
  /// implementations synchronise, and apply what they store at frame end (frames stay
  /// deterministic whatever the thread count).
  virtual void leaving(std::span<const LeavingRadiance> rays) = 0;
  /// Called by render_frame after the last tile: trace_ms is the frame's tracing time, rays the
  /// rays it traced (what a traced ray costs, for hooks that weigh lookups against tracing).
  virtual void end_frame(double /*trace_ms*/, std::uint64_t /*rays*/) {}
  /// The frame's cache counters, for the stats (hooks that cache nothing leave them zero).
  virtual void report(CacheCounts& /*out*/) const {}
};

} // namespace specula
