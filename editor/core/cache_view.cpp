#include "editor/core/cache_view.h"

#include "specula/cache/ray_cache.h"
#include "specula/image/framebuffer.h"
#include "specula/render/scene_layer.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/tracer.h"

#include <limits>
#include <vector>

namespace specula::editor {

namespace {

const vec3 kValid(0.1f, 0.85f, 0.2f);
const vec3 kOutdated(0.95f, 0.1f, 0.1f);
const vec3 kRejected(0.95f, 0.8f, 0.1f);
const vec3 kOff(0.5f, 0.5f, 0.5f);
constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

} // namespace

CacheViewCounts tint_cache_view(Framebuffer& image, const Camera& camera, const SceneLayer& layer,
                                const Tracer& tracer, const cache::RayCacheStore& store) {
  CacheViewCounts counts;
  const SceneTables& tables = layer.tables();
  // The cube of each instance slot, if any.
  std::vector<std::int32_t> cube_of(tables.instances.size(), -1);
  for (std::size_t i = 0; i < store.cube_count(); ++i) {
    const std::uint32_t slot = store.cube(i).instance;
    if (slot < cube_of.size()) cube_of[slot] = std::int32_t(i);
  }
  // Which object each pixel shows: the frame's own camera rays, through the active tracer.
  const std::uint32_t width = image.width(), height = image.height();
  const std::size_t n = std::size_t(width) * height;
  const CameraRays rays(camera, width, height, layer.render_origin());
  std::vector<Ray> camera_rays;
  camera_rays.reserve(n);
  for (std::uint32_t y = 0; y < height; ++y)
    for (std::uint32_t x = 0; x < width; ++x) camera_rays.push_back(rays.ray(x, y));
  std::vector<Hit> hits(n);
  tracer.intersect(camera_rays, hits);
  // Per pixel, the shallowest lookup of a ray leaving the object it shows.
  std::vector<std::uint32_t> record(n, kNone);
  const std::vector<cache::LookupRecord>& log = store.lookup_log();
  for (std::uint32_t k = 0; k < log.size(); ++k) {
    const cache::LookupRecord& r = log[k];
    if (r.pixel >= n || !hits[r.pixel].hit() || hits[r.pixel].instance != r.instance) continue;
    std::uint32_t& best = record[r.pixel];
    if (best == kNone || r.depth < log[best].depth) best = k;
  }
  std::span<vec3> pixels = image.pixels();
  for (std::size_t p = 0; p < n; ++p) {
    const Hit& hit = hits[p];
    if (!hit.hit() || hit.instance >= cube_of.size() || cube_of[hit.instance] < 0) continue;
    vec3 tint = kOff;
    if (!store.cube(std::size_t(cube_of[hit.instance])).enabled) {
      tint = kOff;
      ++counts.off;
    } else if (record[p] == kNone) {
      continue; // no lookup there (lookups off, or its ray's weight under the cut-off)
    } else {
      switch (log[record[p]].outcome) {
      case cache::LookupOutcome::Accepted:
        tint = kValid;
        ++counts.valid;
        break;
      case cache::LookupOutcome::Outdated:
        tint = kOutdated;
        ++counts.outdated;
        break;
      case cache::LookupOutcome::Rejected:
        tint = kRejected;
        ++counts.rejected;
        break;
      }
    }
    pixels[p] = 0.35f * pixels[p] + 0.65f * tint;
  }
  return counts;
}

} // namespace specula::editor
