#pragma once
/// \file
/// The integrators, one per mode, each shading a tile's wave of primary hits (internal to the
/// renderer: render_frame.h is the public entry). Cast and Whitted are separate functions over
/// the same inputs, not branches of one.

#include "specula/render/scene_layer.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/packet_tile.h"
#include "specula/trace/radiance_hook.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/shading.h"
#include "specula/trace/shadow_samples.h"
#include "specula/trace/stats.h"
#include "specula/trace/tracer.h"
#include "specula/trace/vertex_starts.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>
#include <vector>

namespace specula::detail {

/// What every tile of a frame shares.
struct FrameInputs {
  const Tracer& tracer;
  const SceneTables& tables;
  const TraceSettings& settings;
  const CameraRays& camera;
  RadianceHook* hook;
  std::span<vec3> pixels; ///< the image, row-major
  std::uint32_t width;
  bool lookups = false; ///< hook->wants_lookups() at frame start
  bool leaving = false; ///< hook->wants_leaving() at frame start: leaving rays are delivered
  const EmitterTable* emitters = nullptr; ///< the layer's area lights and scene features
  GuideBuffers* guides = nullptr;         ///< path, shadow: primary-hit guides (sized), or none
};

/// A ray of a Whitted tree: one per primary hit and one per reflection or refraction ray. Its
/// radiance is what it brings back: local shading where it lands (filled by its shadow rays) plus,
/// once every wave is done, its children's radiance × their weights.
struct WhittedNode {
  vec3 radiance;
  vec3 weight;     ///< relative to the parent ray
  vec3 throughput; ///< relative to the pixel: decides the weight cut-off
  Ray ray;
  std::uint32_t parent;     ///< node index (kNoInstance for primaries)
  std::uint32_t pixel;      ///< image index
  std::uint32_t tile_pixel; ///< index of the primary node of its pixel
  std::uint32_t depth;
  std::uint32_t from; ///< instance the ray leaves (kNoInstance for primaries)
  RayKind kind;
  bool exits;          ///< it leaves `from` outwards (LeavingRadiance::exits)
  CacheAnswer answer;  ///< how the hook served it
  vec3 cached;         ///< Verify: the value the hook offered
  float hit_t;         ///< its first hit (+inf: none)
  std::uint32_t hit_entity; ///< entity index of its first hit (kNoInstance: none)
  std::uint32_t seen;       ///< entity_bit of everything its subtree hit
  std::uint32_t rays;       ///< rays traced for it and its subtree (itself and shadow rays too)
};

/// Cast mode's wave, one array per component: world position; interpolated vertex normal (then
/// the shading normal); geometric normal facing the ray; the lights' irradiance × cos θ so far.
/// flags: bit 0 a hit on a baked instance, bit 1 its vertex normals are interpolated.
/// `general` lists hits on transformed instances, shaded by shading_point one by one.
struct CastWave {
  std::vector<float> px, py, pz;
  std::vector<float> sx, sy, sz;
  std::vector<float> gx, gy, gz;
  std::vector<float> lr, lg, lb;
  std::vector<std::uint32_t> flags;
  std::vector<std::uint32_t> general;

  void resize(std::size_t n) {
    for (auto* a : {&px, &py, &pz, &sx, &sy, &sz, &gx, &gy, &gz, &lr, &lg, &lb}) a->resize(n);
    flags.resize(n);
  }
};

/// One path of path mode's waves: where it goes next and what it carries. The ray itself is kept
/// beside it (PathWave::rays), ready for the tracer.
struct Path {
  vec3 throughput;      ///< product of BSDF·cos / pdf (and roulette) so far
  float bsdf_pdf;       ///< solid-angle density of the ray's direction (0: camera or specular)
  vec3 previous;        ///< the vertex the ray leaves (MIS: light-sampling density from there)
  std::uint32_t slot;   ///< its sample's radiance entry (PathWave::radiance)
  std::uint32_t pixel;  ///< image index: the sampler's stream
  std::uint32_t stream; ///< PixelSampler(pixel, seed).stream_seed(), hashed once per path
  std::uint32_t sample; ///< index in the pixel's sequence
  /// With a radiance hook: the innermost open leaving record of the path (PathWave::records;
  /// kNoInstance: none), whose `parent` links lead to the enclosing ones.
  std::uint32_t leaving;
};

/// The sample dimensions a path vertex may use, drawn for a whole wave at once
/// (sample_batch.h): the area-light sample (pick, then the point), the roulette decision, the
/// continuation (lobe, reflect or refract, then the diffuse direction).
struct VertexSamples {
  float light[3];
  float roulette;
  float bsdf[4];
};

/// A ray that left an object on a path (with a radiance hook), from the wave that spawned it to
/// the end of its batch: every later contribution to its path's sample is added to `sum` (and
/// to its enclosing records'), so its radiance is sum / throughput at the end.
struct PathLeaving {
  LeavingRadiance ray; ///< radiance, hit_t, hit_entity, seen and rays filled as the path goes on
  vec3 sum;            ///< contributions to the sample since the ray left (throughput-weighted)
  vec3 emitted;        ///< of which the emission at its first hit
  std::uint32_t parent; ///< the enclosing record of the same path (kNoInstance: none)
};

/// A path of the next wave whose ray leaves an object outwards (offered to the hook).
struct PathExit {
  std::uint32_t path;     ///< index in PathWave::paths
  std::uint32_t instance; ///< the instance it leaves
  RayKind kind;
  vec3 weight; ///< the factor the bounce put on the throughput
};

/// Path mode's waves: the live paths and their rays (compacted every wave), the hits, one
/// radiance per sample of the batch, the wave's shadow rays.
struct PathWave {
  std::vector<std::uint32_t> pixel; ///< image index of each tile pixel, in trace order
  std::vector<vec3> sum;            ///< per tile pixel: sum of its finished samples
  std::vector<vec3> radiance;       ///< per sample of the batch
  std::vector<Path> paths, wave_paths, hit_paths;
  std::vector<VertexSamples> samples; ///< per path of the wave being shaded
  std::vector<ShadingPoint> points;   ///< per hit of the wave being shaded (from wave 1 on)
  std::vector<Hit> primary_hits;      ///< wave 0: the tile's primary hits
  std::vector<ShadingPoint> primary_points; ///< and their shading points, for every batch
  VertexStarts starts;                      ///< per path of the wave being shaded (vertex_starts.h)
  std::vector<Ray> rays, wave_rays;
  std::vector<Hit> hits;
  std::vector<Ray> shadow_rays;
  std::vector<std::uint32_t> shadow_slot;
  std::vector<vec3> shadow_value;
  std::vector<std::uint8_t> blocked;
  // With a radiance hook: leaving records of the batch, each shadow ray's record chain, the
  // paths of the next wave that leave an object (index in `paths`), the wave's lookups.
  std::vector<PathLeaving> records;
  std::vector<std::uint32_t> shadow_chain;
  std::vector<PathExit> exits, wave_exits;
  std::vector<std::uint32_t> exit_of; ///< per wave path: its index in wave_exits, or kNoInstance
  std::vector<LeavingQuery> queries;
  std::vector<std::uint32_t> query_path; ///< per query: its wave path
  std::vector<CachedRadiance> answers;
  std::vector<LeavingRadiance> delivered;
};

/// A worker's scratch, reused from tile to tile.
struct TileScratch {
  PrimaryHits primary;
  CastWave cast;
  // Whitted waves.
  std::vector<WhittedNode> nodes;
  std::vector<std::uint32_t> wave, next_wave;
  std::vector<Ray> rays;
  std::vector<Hit> hits;
  std::vector<ShadingPoint> points; ///< per hit of the wave being shaded (shading_batch.h)
  std::vector<Ray> shadow_rays;
  std::vector<std::uint32_t> shadow_node;
  std::vector<vec3> shadow_value;
  std::vector<std::uint8_t> blocked;
  std::vector<std::uint32_t> rays_of_pixel;
  std::vector<LeavingRadiance> leaving;
  // Cache lookups of a wave.
  std::vector<LeavingQuery> queries;
  std::vector<std::uint32_t> query_node;
  std::vector<CachedRadiance> answers;
  std::vector<Ray> confirm_rays;
  std::vector<std::uint32_t> confirm_node;
  std::vector<std::uint8_t> confirm_blocked;
  PathWave path;
  // The shadow caster's lit pixels and one area-light sample of each.
  ShadowSurfaces surfaces;
  ShadowLightRays light_rays;
};

/// What a pixel (or a sample) receives: the radiance, or 0 when it is Inf or NaN, counted in
/// counts.nonfinite so that it is never silent (the stats file's nonfinite_samples).
[[nodiscard]] inline vec3 finite_or_counted(const vec3& radiance, RayCounts& counts) {
  if (std::isfinite(radiance.x) && std::isfinite(radiance.y) && std::isfinite(radiance.z))
    return radiance;
  ++counts.nonfinite;
  return vec3(0.0f);
}

/// The denoiser's guides of a pixel (GuideBuffers): at a primary hit on material `m`, its albedo
/// (the diffuse part's colour, specular parts counted as white: they pass light on untinted), the
/// shading normal and the distance; a miss (m null) gets albedo 1, normal 0 and depth +inf.
inline void write_guide(GuideBuffers& g, std::uint32_t pixel, const gpu::GpuMaterial* m,
                        const vec3& shading_normal = vec3(0.0f),
                        float t = std::numeric_limits<float>::infinity()) {
  if (m == nullptr) {
    g.albedo[pixel] = vec3(1.0f);
    g.normal[pixel] = vec3(0.0f);
    g.depth[pixel] = std::numeric_limits<float>::infinity();
    return;
  }
  const float diffuse = diffuse_weight(*m);
  g.albedo[pixel] = diffuse * m->base_color + (1.0f - diffuse);
  g.normal[pixel] = shading_normal;
  g.depth[pixel] = t;
}

/// Local shading of every primary hit: emission plus the diffuse term of every light, no shadow
/// rays, no secondary rays; misses get the background.
void cast_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
               RayCounts& counts);

/// The Whitted tree of every primary hit, traced in waves: shading a wave emits shadow rays
/// (traced as one batch, then added to the ray they serve) and reflection/refraction rays (the
/// next wave). Leaving rays are delivered to frame.hook after the last wave.
void whitted_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
                  RayCounts& counts);

/// Path tracing (trace/path_integrator.cpp): settings.spp paths per pixel from the tile's primary
/// hits, each a chain of waves, with next-event estimation and MIS; writes their mean.
void path_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
               RayCounts& counts);

/// The shadow caster (trace/shadow_integrator.cpp): primary visibility, one shadow ray per point
/// light and settings.shadow_samples stratified samples of the area lights, local shading only.
void shadow_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
                 RayCounts& counts);

/// The Whitted radiance along arbitrary rays, each the root of its tree at depth `depth` (1: a
/// ray leaving a primary hit). Hits on instance `skip` are passed through (a ray-cache cube's
/// prefill traces from the cube's centre, inside its own object). frame.pixels is not touched
/// and no hook is called.
void whitted_rays(const FrameInputs& frame, std::span<const Ray> rays, std::uint32_t depth,
                  std::uint32_t skip, TileScratch& scratch, RayCounts& counts,
                  std::span<RadianceSample> out);

} // namespace specula::detail
