#pragma once
/// \file
/// Frame rendering: the image is cut into square tiles handed out dynamically to worker threads
/// (TBB work stealing inside an arena of the requested size). Each tile's camera rays are traced
/// by the backend as coherent packets into a wave of primary hits; the integrator of the chosen
/// mode then shades the wave — cast mode locally, Whitted mode by emitting shadow and secondary
/// rays into batches that the backend traces wave after wave until no ray is left (the streaming
/// model of Purcell et al. 2002: no recursion, every ray carries its pixel, weight, kind and the
/// entity it leaves). Pixels are independent and nothing is random, so the image is bit-identical
/// whatever the thread count, tile size or packet width.

#include "specula/image/denoise.h"
#include "specula/image/framebuffer.h"
#include "specula/render/scene_layer.h"
#include "specula/scene/components/camera.h"
#include "specula/trace/radiance_hook.h"
#include "specula/trace/stats.h"
#include "specula/trace/trace_mode.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

namespace specula {

/// How path mode reaches area lights: multiple importance sampling of both strategies (power
/// heuristic), BSDF sampling only (emitters found by chance), or light sampling only (next-event
/// estimation; emitters hit by BSDF-sampled rays after a diffuse bounce add nothing).
enum class LightSampling : std::uint8_t { Mis, Bsdf, Light };
[[nodiscard]] std::optional<LightSampling> parse_light_sampling(std::string_view name);
[[nodiscard]] const char* light_sampling_name(LightSampling sampling);

struct TraceSettings {
  TraceMode mode = TraceMode::Whitted;
  /// Longest chain of reflection/refraction bounces after the primary hit.
  std::uint32_t max_depth = 5;
  /// A secondary ray whose weight (largest channel of its throughput) falls below this is not
  /// traced: its contribution cannot show in an 8-bit image (1/256).
  float min_weight = 1.0f / 256.0f;
  vec3 background{0.0f};
  /// Whitted: trace shadow rays (off: every light counts as visible — the "diffuse" and
  /// "reflection & refraction" configurations of the real-time ray tracer paper's tables).
  bool shadows = true;
  std::uint32_t tile_size = 16;
  std::uint32_t threads = 0; ///< 0: every hardware thread
  // The stochastic modes (path, shadow). A pixel's samples are positions in its own
  // low-discrepancy sequence (trace/sampler.h): this frame uses [sample_offset, sample_offset +
  // spp) (path) or [sample_offset, sample_offset + shadow_samples) (shadow), so frames that
  // advance the offset continue one sequence and the image never depends on threads or tiles.
  std::uint32_t spp = 1;            ///< path: samples per pixel in this frame
  std::uint32_t shadow_samples = 1; ///< shadow: area-light samples per pixel in this frame
  LightSampling sampling = LightSampling::Mis;
  std::uint32_t seed = 0;          ///< scrambles every pixel's sequence
  std::uint32_t sample_offset = 0; ///< index of this frame's first sample in each sequence
};

/// Most area-light samples per pixel a shadow-mode frame may take (prepare_rendering checks it).
inline constexpr std::uint32_t kMaxShadowSamples = 4096;

/// Most secondary rays one pixel may spawn in a frame (a bound on memory for pathological
/// scenes, e.g. facing glass with no weight cut-off); rays beyond it are counted as dropped.
inline constexpr std::uint32_t kMaxRaysPerPixel = 4096;

/// Renders one frame of the scene layer's tables into `out` (its size is the image size) with
/// `tracer`, whose structures must be up to date with `layer`. `camera` is in world space; its
/// rays are made relative to the layer's render origin. Leaving rays go to `hook` when one
/// is given. Path and shadow modes write the mean of the frame's samples, and, when `guides` is
/// given, the primary hits' albedo, normal and depth for the denoiser (resized to the image).
/// Returns the ray counts (FrameStats::trace_ms and ms are left to the caller).
/// Throws UnavailableError for modes this build does not have.
FrameStats render_frame(const Tracer& tracer, const SceneLayer& layer, const Camera& camera,
                        const TraceSettings& settings, Framebuffer& out,
                        RadianceHook* hook = nullptr, GuideBuffers* guides = nullptr);

/// What a ray brought back (trace_radiance).
struct RadianceSample {
  vec3 radiance{0.0f};
  float t = 0.0f;                    ///< its first hit (+inf: none)
  std::uint32_t entity = kNoInstance; ///< entity index of its first hit
  std::uint32_t seen = 0;            ///< entity_bit (radiance_hook.h) of all its subtree hit
  std::uint32_t rays = 0;            ///< rays traced for it: itself, shadow rays, its subtree
};

/// The Whitted radiance along arbitrary rays, each the root of a tree at depth `depth` (1: like
/// a ray leaving a primary hit, so max_depth − 1 more bounces), in parallel; hits on instance
/// `skip` (kNoInstance: none) are passed through. No hook is called. Returns the ray counts.
RayCounts trace_radiance(const Tracer& tracer, const SceneLayer& layer,
                         const TraceSettings& settings, std::span<const Ray> rays,
                         std::uint32_t depth, std::uint32_t skip, std::span<RadianceSample> out);

/// The primary-ray stage of render_frame alone (camera rays, coherent packets, hits resolved to
/// instances), for measuring the tracer's own overhead against its backend. Returns a checksum.
/// `render_origin` is the render origin of the layer the tracer was built from.
std::uint64_t trace_primary_frame(const Tracer& tracer, const Camera& camera, std::uint32_t width,
                                  std::uint32_t height, const TraceSettings& settings,
                                  const dvec3& render_origin = dvec3(0.0));

} // namespace specula
