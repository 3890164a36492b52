#include "specula/trace/render_frame.h"

#include "specula/core/error.h"
#include "specula/trace/integrators.h"

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <string>
#include <thread>

namespace specula {
namespace {

/// Worker threads for `threads` (0: every hardware thread).
int worker_count(std::uint32_t threads) {
  return threads > 0 ? int(threads) : int(std::max(1u, std::thread::hardware_concurrency()));
}

/// Denormals slow CPU traversal down (and make Embree warn): flushed while tracing, the thread's
/// (possibly the caller's) own mode given back afterwards.
class DenormalsFlushed {
public:
  DenormalsFlushed() : saved_(_mm_getcsr()) {
    _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
    _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
  }
  ~DenormalsFlushed() { _mm_setcsr(saved_); }
  DenormalsFlushed(const DenormalsFlushed&) = delete;
  DenormalsFlushed& operator=(const DenormalsFlushed&) = delete;

private:
  unsigned int saved_;
};

/// Runs f(scratch, tile) for every tile of a width × height image, tiles handed out dynamically
/// to `threads` workers (0: all), each worker with its own scratch. TBB's default partitioner
/// splits the tile range adaptively and idle workers steal halves of busy ones' ranges, so
/// neighbouring tiles usually run on one worker back to back (cache-friendly) while the load still
/// balances; one task per tile measured slower here.
template <typename F>
void for_each_tile(std::uint32_t width, std::uint32_t height, std::uint32_t tile,
                   std::uint32_t threads, std::uint32_t packet_width, F&& f) {
  tile = std::max(1u, tile);
  const std::uint32_t tiles_x = (width + tile - 1) / tile;
  const std::uint32_t tiles_y = (height + tile - 1) / tile;
  tbb::task_arena arena(worker_count(threads));
  tbb::enumerable_thread_specific<detail::TileScratch>
      scratch; // one per worker, reused across tiles
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, tiles_x * tiles_y, 1),
                      [&](const tbb::blocked_range<std::uint32_t>& range) {
                        const DenormalsFlushed flushed;
                        detail::TileScratch& local = scratch.local();
                        for (std::uint32_t t = range.begin(); t != range.end(); ++t) {
                          const std::uint32_t x0 = (t % tiles_x) * tile;
                          const std::uint32_t y0 = (t / tiles_x) * tile;
                          f(local,
                            PacketTile::for_width(x0, y0, std::min(x0 + tile, width),
                                                  std::min(y0 + tile, height), packet_width));
                        }
                      });
  });
}

} // namespace

std::optional<TraceMode> parse_trace_mode(std::string_view name) {
  if (name == "cast") return TraceMode::Cast;
  if (name == "whitted") return TraceMode::Whitted;
  if (name == "path") return TraceMode::Path;
  if (name == "shadow") return TraceMode::Shadow;
  return std::nullopt;
}

const char* trace_mode_name(TraceMode mode) {
  switch (mode) {
  case TraceMode::Cast:
    return "cast";
  case TraceMode::Whitted:
    return "whitted";
  case TraceMode::Path:
    return "path";
  case TraceMode::Shadow:
    return "shadow";
  }
  return "unknown";
}

std::optional<LightSampling> parse_light_sampling(std::string_view name) {
  if (name == "mis") return LightSampling::Mis;
  if (name == "bsdf") return LightSampling::Bsdf;
  if (name == "light") return LightSampling::Light;
  return std::nullopt;
}

const char* light_sampling_name(LightSampling sampling) {
  switch (sampling) {
  case LightSampling::Mis:
    return "mis";
  case LightSampling::Bsdf:
    return "bsdf";
  case LightSampling::Light:
    return "light";
  }
  return "unknown";
}

std::uint64_t trace_primary_frame(const Tracer& tracer, const Camera& camera, std::uint32_t width,
                                  std::uint32_t height, const TraceSettings& settings,
                                  const dvec3& render_origin) {
  const CameraRays camera_rays(camera, width, height, render_origin);
  std::atomic<std::uint64_t> checksum{0};
  for_each_tile(width, height, settings.tile_size, settings.threads, tracer.packet_width(),
                [&](detail::TileScratch& scratch, const PacketTile& tile) {
                  tracer.intersect_camera(camera_rays, tile, scratch.primary);
                  std::uint64_t local = 0;
                  for (std::size_t i = 0; i < scratch.primary.size(); ++i)
                    local += scratch.primary.instance[i] + scratch.primary.primitive[i];
                  checksum += local;
                });
  return checksum.load();
}

FrameStats render_frame(const Tracer& tracer, const SceneLayer& layer, const Camera& camera,
                        const TraceSettings& settings, Framebuffer& out, RadianceHook* hook,
                        GuideBuffers* guides) {
  if (FrameStats device; tracer.render_frame_on_device(layer, camera, settings, out, hook, guides,
                                                       device))
    return device;
  const bool stochastic = settings.mode == TraceMode::Path || settings.mode == TraceMode::Shadow;
  if (guides != nullptr) guides->resize(std::size_t(out.width()) * out.height());
  const auto start = std::chrono::steady_clock::now();
  const CameraRays camera_rays(camera, out.width(), out.height(), layer.render_origin());
  if (hook != nullptr) hook->begin_frame(out.width(), out.height(), settings.mode);
  const bool lookups = hook != nullptr &&
                       (settings.mode == TraceMode::Whitted || settings.mode == TraceMode::Path) &&
                       hook->wants_lookups();
  const detail::FrameInputs frame{tracer,
                                  layer.tables(),
                                  settings,
                                  camera_rays,
                                  hook,
                                  out.pixels(),
                                  out.width(),
                                  lookups,
                                  hook != nullptr && hook->wants_leaving(),
                                  &layer.emitters(),
                                  stochastic ? guides : nullptr};
  tbb::combinable<RayCounts> counts;
  const TraceMode mode = settings.mode;
  for_each_tile(out.width(), out.height(), settings.tile_size, settings.threads,
                tracer.packet_width(), [&](detail::TileScratch& scratch, const PacketTile& tile) {
                  tracer.intersect_camera(camera_rays, tile, scratch.primary);
                  switch (mode) {
                  case TraceMode::Cast:
                    detail::cast_tile(frame, tile, scratch, counts.local());
                    break;
                  case TraceMode::Whitted:
                    detail::whitted_tile(frame, tile, scratch, counts.local());
                    break;
                  case TraceMode::Path:
                    detail::path_tile(frame, tile, scratch, counts.local());
                    break;
                  case TraceMode::Shadow:
                    detail::shadow_tile(frame, tile, scratch, counts.local());
                    break;
                  }
                });
  FrameStats stats;
  counts.combine_each([&](const RayCounts& c) { stats.rays += c; });
  if (hook != nullptr)
    hook->end_frame(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count(),
        stats.rays.total());
  return stats;
}

RayCounts trace_radiance(const Tracer& tracer, const SceneLayer& layer,
                         const TraceSettings& settings, std::span<const Ray> rays,
                         std::uint32_t depth, std::uint32_t skip, std::span<RadianceSample> out) {
  if (out.size() != rays.size()) throw Error("trace_radiance", "out and rays differ in size");
  const CameraRays camera(Camera{}, 1, 1); // unused: the roots are given
  const detail::FrameInputs frame{tracer, layer.tables(), settings, camera,           nullptr, {},
                                  0,      false,          false,    &layer.emitters()};
  tbb::combinable<RayCounts> counts;
  tbb::enumerable_thread_specific<detail::TileScratch> scratch;
  constexpr std::size_t kChunk = 256;
  const std::size_t chunks = (rays.size() + kChunk - 1) / kChunk;
  tbb::task_arena arena(worker_count(settings.threads));
  arena.execute([&] {
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
      const DenormalsFlushed flushed;
      const std::size_t first = c * kChunk;
      const std::size_t n = std::min(kChunk, rays.size() - first);
      detail::whitted_rays(frame, rays.subspan(first, n), depth, skip, scratch.local(),
                           counts.local(), out.subspan(first, n));
    });
  });
  RayCounts total;
  counts.combine_each([&](const RayCounts& c) { total += c; });
  return total;
}

} // namespace specula
