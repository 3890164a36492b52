#pragma once
/// \file
/// Ray-cache cubes (Ruff, Clua, Fernandes 2013) made to work for moving objects: per reflective
/// or refractive entity a cube of six faces of texels, each holding the colour a ray leaving the
/// object in that direction brought back, the distance from the cube centre to what it hit, that
/// entity, a summary of everything its subtree saw, and a valid flag. The store is the renderer's
/// leaving-radiance hook (trace/radiance_hook.h): integrators ask it about every ray that exits a
/// cached object before tracing it, and hand it the radiance of those they traced; writes wait
/// for the end of the frame (deterministic whatever the thread count). The visibility graph (what
/// each cube's valid texels saw) drives invalidation when entities move
/// (cache_invalidation_system); the auto policy measures per cube what lookups save against what
/// tracing costs and what error they bring, and stops caching where it does not pay.
/// docs/design/ray-cache.md has the whole account.

#include "specula/cache/cache_settings.h"
#include "specula/core/math.h"
#include "specula/ecs/registry.h"
#include "specula/render/scene_layer.h"
#include "specula/trace/radiance_hook.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/sampler.h"
#include "specula/trace/stats.h"

#include <atomic>
#include <cmath>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace specula::cache {

/// One texel, 16 bytes: colour and distance as half floats, the first hit's entity index, a
/// 16-bit summary of the entities the ray's subtree hit (bit = entity index mod 16), what tracing
/// it cost in rays (saturating at 255: what a lookup saves), the state.
struct Texel {
  std::uint16_t rgb[3] = {0, 0, 0};
  std::uint16_t distance = 0x7c00; ///< +inf as a half: the ray left the scene
  std::uint32_t hit = 0xffffffffu; ///< entity index of the first hit (none: 0xffffffff)
  std::uint16_t seen = 0;
  std::uint8_t rays = 0;  ///< rays its subtree traced (itself, shadow rays, bounces)
  std::uint8_t state = 0; ///< kOutdated or kValid, | kTexelPrefilled when traced from the centre
  [[nodiscard]] bool valid() const { return (state & kValidBit) != 0; }
  static constexpr std::uint8_t kValidBit = 1;
};
static_assert(sizeof(Texel) == 16);
inline constexpr std::uint8_t kOutdated = 0;
inline constexpr std::uint8_t kValid = Texel::kValidBit;
inline constexpr std::uint8_t kTexelPrefilled = 2;

[[nodiscard]] Texel make_texel(const vec3& radiance, float distance, std::uint32_t hit_entity,
                               std::uint32_t seen, std::uint32_t rays);
[[nodiscard]] vec3 texel_radiance(const Texel& t);
[[nodiscard]] float texel_distance(const Texel& t);
/// The 32-bit entity mask folded to the texel's 16 bits.
[[nodiscard]] inline std::uint16_t fold_seen(std::uint32_t seen) {
  return std::uint16_t((seen ^ (seen >> 16)) & 0xffffu);
}
[[nodiscard]] inline std::uint16_t seen_bit16(std::uint32_t entity_index) {
  return std::uint16_t(1u << (entity_index & 15u));
}

/// Path mode's per-texel radiance probe (docs/design/ray-cache.md, "Path mode"): an exponential
/// moving average of the path samples that left the owner through the texel, batch by batch
/// (one batch a frame): at each batch sum ← (1 − α)·sum + the batch's sum, weight likewise with
/// its count, so the mean weighs every batch alike once it has been served for a few frames. A
/// texel serves lookups while its weight is at least CacheSettings::path_samples.
struct ProbeTexel {
  float sum[3] = {0.0f, 0.0f, 0.0f};
  float weight = 0.0f;       ///< the samples' count, averaged like the sum
  std::uint32_t lookups = 0; ///< lookups of its direction in the latest frame that had any
  std::uint32_t samples = 0; ///< samples it has taken since it was last outdated
  std::uint32_t reserved[2] = {0, 0};
};
static_assert(sizeof(ProbeTexel) == 32);
/// α of the probes' moving average: a batch's weight halves in about five frames.
inline constexpr float kProbeDecay = 0.125f;

/// Path mode's probe of the light arriving at a cube's object (RayCacheStore::irradiance): the
/// directions cut into min(resolution, kIncomingCells)² cells a face, each a moving average (as
/// ProbeTexel's) of the whole radiance traced leaving rays brought back through it — emission at
/// their first hit included. From it, nine spherical-harmonic coefficients of the irradiance
/// (Ramamoorthi & Hanrahan 2001) light the object's own diffuse lobe.
struct IncomingCell {
  float sum[3] = {0.0f, 0.0f, 0.0f};
  float weight = 0.0f;
};
inline constexpr std::uint32_t kIncomingCells = 16;
/// The incoming-light probe lights diffuse lobes once its sampled cells cover this share of
/// the sphere of directions (the rest take the mean of those sampled). Leaving rays are
/// reflections of what the camera sees: the directions straight behind the object, which only
/// its silhouette reflects, get few samples or none (a sphere half the height of a 48² image
/// covers 57% of 16² cells).
inline constexpr float kIncomingCoverage = 0.5f;
/// The probe is of the light at the object's centre, so it stands for every point of the object
/// only where what the object sees is far: it lights diffuse lobes while at most kNearShare of
/// the leaving rays a frame hit something within kNearRadii of the object's bounding radius.
inline constexpr float kNearRadii = 10.0f;
inline constexpr float kNearShare = 0.1f;

/// Nine coefficients of an irradiance: E(n) = Σ c_i · Y_i(n), the cosine convolution folded in.
struct IrradianceSH {
  vec3 c[9] = {};
  /// (1/π)∫ L(s) max(0, n·s) ds for unit n, not below 0.
  [[nodiscard]] vec3 evaluate(const vec3& n) const;
};
/// The coefficients from `cells` (6·side² IncomingCells, unsampled ones taking the mean of the
/// sampled); `coverage` gets the sampled share of the sphere.
[[nodiscard]] IrradianceSH project_irradiance(std::span<const IncomingCell> cells,
                                              std::uint32_t side, float& coverage);

/// A world-space bounding sphere.
struct Sphere {
  vec3 centre{0.0f};
  float radius = 0.0f;
};

/// The state of one cube, as the tests and the report read it.
struct CubeView {
  ecs::Entity owner;
  std::uint32_t instance;
  std::uint32_t resolution;
  vec3 centre;
  std::span<const Texel> texels;
  std::span<const ProbeTexel> probe; ///< path mode: per texel (empty in other modes)
  LookupMode mode;
  bool enabled;
  float cos_tau;
  /// Changes whenever a texel does (from a process-wide counter: never reused, even by a cube
  /// made anew), so a device copy re-uploads only the cubes that changed.
  std::uint64_t generation;
  /// The texels changed (some perhaps more than once) since generation `changes_from`, when
  /// the cube kept track (0 when it did not: a flush, or too many changes): a copy made at that
  /// generation needs only these (RayCacheStore::restart_journals).
  std::uint64_t changes_from;
  std::span<const std::uint32_t> changes;
  /// Auto, Whitted frames: one accepted lookup in this many is traced anyway to measure the
  /// error (verify_chosen); 0: none (policy on).
  std::uint32_t verify_every;
  /// Path mode: the incoming-light probe (6·incoming_side² cells; empty in other modes or off)
  std::span<const IncomingCell> incoming;
  std::uint32_t incoming_side;
  bool lights_diffuse; ///< path mode: its incoming light lights its object's diffuse lobe
};

/// Which accepted Whitted lookups auto traces anyway (CacheAnswer::Verify): one in `every`, by a
/// 32-bit hash of the lookup (pixel, depth, sample, the store's frame, the cube's index), so that
/// the choice depends on no thread count and the device kernels make it alike
/// (shaders/include/frame_cache.glsl).
[[nodiscard]] constexpr bool verify_chosen(std::uint32_t pixel, std::uint32_t depth,
                                           std::uint32_t sample, std::uint32_t frame,
                                           std::uint32_t cube, std::uint32_t every) {
  const std::uint32_t h = hash_combine(
      hash_combine(hash_combine(hash_u32(pixel), depth | (sample << 8)), frame), cube);
  return every != 0 && h % every == 0;
}

/// The march's test that a point's direction from the centre lies within half a texel of the
/// ray's (its cosine) on a cube of `resolution`: one expression for the store and for the device
/// kernels, which take the value from the host (GpuCube::cos_half_texel).
[[nodiscard]] inline float march_cos_half_texel(std::uint32_t resolution) {
  const float texel_angle = 2.0f / float(resolution);
  return std::cos(0.5f * texel_angle);
}

/// What a lookup found in its texel (RayCacheStore::lookup_log).
enum class LookupOutcome : std::uint8_t {
  Accepted, ///< valid, and its mode's test accepted it (served, or confirmed, or verified)
  Outdated, ///< not valid: traced
  Rejected, ///< valid, but its parallax test (tau, march; path mode: another surface) refused it
};

/// One lookup of the latest frame, by pixel.
struct LookupRecord {
  std::uint32_t pixel, depth, instance;
  LookupOutcome outcome;
};

/// What one invalidation did.
struct InvalidationStats {
  std::uint64_t outdated = 0;  ///< texels this invalidation outdated
  std::uint64_t flush_all = 0; ///< valid texels before it (what flushing every cube would cost)
};

/// What a frame's lookups and unrecorded leaving rays added to one cube, counted where they
/// were made (the device frames' kernels, DeviceCache) instead of by lookup() and leaving().
struct CubeFrameCounts {
  std::uint64_t lookups = 0, outdated = 0, rejected = 0, march_steps = 0;
  std::uint64_t offered_rays = 0;            ///< what the served texels cost when they were traced
  std::uint64_t used = 0, used_rays = 0;     ///< served leaving rays, and the rays they traced
  std::uint64_t traced = 0, traced_rays = 0; ///< traced leaving rays, and their subtrees' rays
  friend bool operator==(const CubeFrameCounts&, const CubeFrameCounts&) = default;
};

class RayCacheStore final : public RadianceHook {
public:
  explicit RayCacheStore(CacheSettings settings);
  ~RayCacheStore() override;

  [[nodiscard]] const CacheSettings& settings() const { return settings_; }

  /// Brings the set of cubes up to date with the registry (entities with RayCacheCube whose
  /// material reflects or transmits, and an instance in the layer) and applies the layer's
  /// latest delta: texels that saw a moved, deformed, added or removed entity (first hit, or in
  /// their subtree), that now look at its new bounds, or whose hit point lies in its old or new
  /// shadow are outdated; an owner that moved outdates its whole cube; light or material changes
  /// outdate every texel that hit a surface; a rebuilt static set outdates everything.
  /// The registry is only read (its views need a non-const one).
  InvalidationStats invalidate(ecs::Registry& registry, const SceneLayer& layer);

  /// Traces every outdated texel of every enabled cube from the cube's centre (passing through
  /// its owner) and stores the result: the ideal, fully filled cache (--cache-prefill). Nothing
  /// in path mode (its texels average path samples, not one traced value).
  std::uint64_t prefill(const Tracer& tracer, const SceneLayer& layer,
                        const TraceSettings& trace);

  /// Fill ahead of the view (--cache-fill-ahead K): traces up to K outdated texels and stores
  /// them, choosing by rings of tiles around the tiles the lookups since the last call addressed
  /// (ring 0: those tiles; ring r + 1: their neighbours, across face edges), nearest ring first,
  /// spread by a hash within a ring, at most kFillAheadRings rings out. A texel's ray leaves from
  /// where the view will look it up: the point of the owner's bounding sphere that reflects its
  /// direction towards `eye` (from the centre without an eye). A panning view then finds the
  /// texels it turns to already valid. Nothing in path mode, with no lookups since the last call,
  /// or with K = 0.
  std::uint64_t fill_ahead(const Tracer& tracer, const SceneLayer& layer,
                           const TraceSettings& trace, const std::optional<vec3>& eye);
  /// Fill ahead's tiles: a face has min(resolution, kFillAheadTiles)² of them.
  static constexpr std::uint32_t kFillAheadTiles = 64;
  /// How far fill ahead looks: rings of tiles around the addressed ones (8 tiles of 64 a face:
  /// about 11° at a face's centre).
  static constexpr std::uint32_t kFillAheadRings = 8;

  // RadianceHook
  /// A frame in a different estimator than the last (Whitted's exact radiance, path mode's
  /// one-sample estimates, which include indirect light) starts every cube afresh.
  void begin_frame(std::uint32_t width, std::uint32_t height, TraceMode mode) override;
  [[nodiscard]] bool wants_lookups() const override;
  /// Views (the editor's cache view) ask for every lookup's outcome by pixel: off by default.
  void set_log_lookups(bool on) { log_lookups_ = on; }
  /// The lookups of the frame since the latest begin_frame, in no particular order (batches
  /// append as their threads finish), with set_log_lookups on.
  [[nodiscard]] const std::vector<LookupRecord>& lookup_log() const { return lookup_log_; }
  /// Starts every cube's list of changed texels afresh from its current generation
  /// (CubeView::changes): the device copy calls it once it is up to date. A second copy finds
  /// the lists started at another generation than its own and sends whole cubes.
  void restart_journals();
  /// Whether every lookup of the frame must reach lookup() itself (the lookup log, or fill
  /// ahead's tile marks): then no one may count lookups for it (add_frame_counts).
  [[nodiscard]] bool needs_every_lookup() const;
  /// Cube i's counts of the frame so far (since begin_frame).
  [[nodiscard]] CubeFrameCounts frame_counts(std::size_t i) const;
  /// Adds lookups and leaving rays counted elsewhere to cube i's frame, as lookup() and leaving()
  /// would have counted them (between begin_frame and end_frame). Rays that may write a texel or
  /// that were verified must still reach leaving().
  void add_frame_counts(std::size_t i, const CubeFrameCounts& n);
  /// The frame number verify_chosen hashes (counted by begin_frame; its low 32 bits).
  [[nodiscard]] std::uint32_t verify_frame() const { return std::uint32_t(frame_); }
  /// True unless every cube is off.
  [[nodiscard]] bool wants_leaving() const override;
  /// Path mode, with path_irradiance: the cube's incoming-light probe, once it covers
  /// kIncomingCoverage of the sphere, lights its object's diffuse lobe (IrradianceSH).
  [[nodiscard]] bool irradiance(std::uint32_t instance, const vec3& n, vec3& out) const override;
  void lookup(std::span<const LeavingQuery> queries,
              std::span<CachedRadiance> answers) const override;
  void leaving(std::span<const LeavingRadiance> rays) override;
  void end_frame(double trace_ms, std::uint64_t rays) override;
  void report(CacheCounts& out) const override;

  /// The latest frame's counters (end_frame) and invalidation (invalidate).
  [[nodiscard]] const CacheCounts& counts() const { return counts_; }
  [[nodiscard]] std::size_t cube_count() const;
  [[nodiscard]] CubeView cube(std::size_t i) const;
  /// The cube of an entity, if it has one.
  [[nodiscard]] std::optional<std::size_t> cube_of(ecs::Entity owner) const;
  /// Entities (by index) the valid texels of cube i saw first, with texel counts: the visibility
  /// graph's edges from that cube.
  [[nodiscard]] std::vector<std::pair<std::uint32_t, std::uint32_t>> edges(std::size_t i) const;
  /// Marks every texel of every cube outdated; returns how many were valid.
  std::uint64_t flush();

  struct Cube;

private:
  /// Auto: verify_chosen's period for cube `c` (shorter while a mode is being evaluated).
  [[nodiscard]] std::uint32_t verify_period(const Cube& c) const;
  std::uint64_t apply_writes();
  /// Path mode: the frame's samples into each cube's incoming-light probe, and its irradiance.
  void fold_incoming();
  /// Path mode: whether texels serve leaving rays (--cache-serve on, never under auto).
  [[nodiscard]] bool serving() const;
  /// Traces texels `todo` of cube c and stores them, flagged prefilled: from the centre, or with
  /// an eye from the point of the bounding sphere that reflects each towards it. `ahead`: fill
  /// ahead's, whose rays the cube's savings must cover (prefill, the ideal bound, is free).
  std::uint64_t trace_texels(Cube& c, std::span<const std::uint32_t> todo, const Tracer& tracer,
                             const SceneLayer& layer, const TraceSettings& trace,
                             const std::optional<vec3>& eye, bool ahead);
  void decide(Cube& c, double ns_per_ray, double frame_rays);
  /// Auto: where a cube starts (its ladder's first rung; in path mode, off).
  void start_auto(Cube& c) const;

  CacheSettings settings_;
  std::vector<std::unique_ptr<Cube>> cubes_;
  std::vector<std::int32_t> cube_of_instance_; ///< by instance slot, -1: none
  std::vector<Sphere> bounds_;                 ///< by entity index, as last invalidated
  std::vector<std::uint8_t> has_bounds_;
  std::uint64_t synced_ = 0; ///< SceneLayer::syncs() of the last invalidation (0: none)
  std::uint32_t width_ = 1, height_ = 1;
  std::uint64_t frame_ = 0;
  bool lookups_ = false;
  bool averaging_ = false; ///< path mode: texels average samples (the probes)
  CacheCounts counts_;
  InvalidationStats last_invalidation_;
  std::uint64_t pending_prefilled_ = 0;
  struct Candidate;
  std::mutex mutex_;
  bool log_lookups_ = false;
  mutable std::mutex log_mutex_;
  mutable std::vector<LookupRecord> lookup_log_;
  std::vector<Candidate> candidates_;
};

/// The registry resource holding the store (the render job's hook points at the same object):
/// cache_invalidation_system reaches it here.
struct RayCaches {
  std::shared_ptr<RayCacheStore> store;
};

} // namespace specula::cache
