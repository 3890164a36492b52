#pragma once
/// \file
/// The render job: registry resources holding what the scene-layer, acceleration and render
/// systems need (the scene layer, the tracer chosen once at start-up, trace settings, the image)
/// and what they report (the last frame's stats).

#include "specula/cache/cache_settings.h"
#include "specula/ecs/registry.h"
#include "specula/image/denoise.h"
#include "specula/image/framebuffer.h"
#include "specula/render/accumulation.h"
#include "specula/render/scene_layer.h"
#include "specula/render/tracer_factory.h"
#include "specula/trace/radiance_hook.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/stats.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace specula {

/// Most samples per pixel one path-mode frame may take (`--spp`).
inline constexpr std::uint32_t kMaxSpp = 65536;

struct RenderJob {
  /// The backend asked for (`auto` or a name, see render/tracer_factory.h); prepare_rendering
  /// replaces it with the one chosen.
  std::string backend = "auto";
  /// Primary-ray packet width (1, 4, 8, 16); 16 measured fastest here (docs/PERFORMANCE.md).
  std::uint32_t packet_width = 16;
  /// How the Vulkan backends run (execution style, device frames, grid density); CPU backends
  /// ignore it.
  GpuTracerOptions gpu;
  /// Native backends: false traces single rays through the binary BVHs, not their 4-wide
  /// collapse, as the Vulkan device does (TracerOptions::native_wide_bvh).
  bool native_wide_bvh = true;
  /// For path and shadow modes, settings.sample_offset is where the first frame after every
  /// restart starts; later frames continue from there (Accumulation).
  TraceSettings settings;
  /// What the job shows: the frame (cast, Whitted), the mean of the accumulated frames (path,
  /// shadow), or that mean denoised when `denoise` is set.
  Framebuffer image{1, 1};
  /// Path and shadow modes: average the frames while nothing changes (Accumulation); off, every
  /// frame is shown on its own (its sample offset still advances: new noise each frame).
  bool accumulate = true;
  /// Path and shadow modes: filter the shown mean with the à-trous denoiser (image/denoise.h),
  /// guided by the primary hits of the latest frame and, from the second accumulated frame on, by
  /// each pixel's variance over the frames (`moments`); threads 0 takes settings.threads.
  std::optional<DenoiseSettings> denoise;
  /// Ray-cache cubes: with a policy other than off, prepare_rendering creates the cache store
  /// (the cache::RayCaches resource) and makes it the hook.
  cache::CacheSettings cache;
  /// Receives the radiance of every leaving ray (none: integrators skip that bookkeeping).
  std::shared_ptr<RadianceHook> hook;
  /// The latest frame: ms is the whole tick (set by the schedule), trace_ms the render system's.
  FrameStats last;
  std::uint64_t frames = 0;

  /// Path and shadow modes' running mean (render_job_frame keeps it).
  Accumulation accumulation;
  /// The latest frame's own samples (path and shadow while accumulating or denoising).
  Framebuffer frame{1, 1};
  /// The noisy mean when denoising (image then holds the denoised one).
  Framebuffer noisy{1, 1};
  /// The latest frame's primary-hit guides, filled when denoising.
  GuideBuffers guides;
  /// When denoising: the accumulated frames' per-pixel moments (restarted with the mean).
  LuminanceMoments moments;

  /// The undenoised image: the mean of the accumulated frames in path and shadow modes (for
  /// measuring error), the frame otherwise.
  [[nodiscard]] const Framebuffer& noisy_image() const {
    return denoise && stochastic_mode(settings.mode) ? noisy : image;
  }
};

/// The tracer the job renders with (a resource, so systems reach it without naming its type).
struct ActiveTracer {
  std::unique_ptr<Tracer> tracer;
};

/// Renders the job's next frame of the layer's scene from `camera` into job.image with `tracer`
/// (up to date with `layer`): directly in cast and Whitted modes; in path and shadow modes
/// through job.accumulation, restarting it when the layer's delta is not empty (the sync of this
/// tick saw a change) or the camera or settings changed, then denoising when asked. Returns the
/// frame's stats (ray counts, accumulated samples, restart, denoise_ms; trace_ms and ms are left
/// to the caller). Throws UnavailableError for a mode or denoiser this build does not have.
FrameStats render_job_frame(RenderJob& job, const Tracer& tracer, const SceneLayer& layer,
                            const Camera& camera);

/// Checks the job's settings, creates its tracer through the factory and installs the job, the
/// tracer and a SceneLayer in the registry; the schedule's scene-layer, acceleration and render
/// systems then run on every tick. Throws UnavailableError for a backend or mode this build or
/// machine does not have, specula::Error for bad settings (packet width, tile size, a depth above
/// kMaxTraceDepth, the limit every scene loader applies too; spp outside 1 … kMaxSpp, shadow
/// samples outside 1 … kMaxShadowSamples; a sample offset without room for one frame's samples
/// below 2^32; a denoiser in a mode other than path and shadow).
void prepare_rendering(ecs::Registry& registry, RenderJob job);

} // namespace specula
