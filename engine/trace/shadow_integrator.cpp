// The shadow caster (Purcell et al. 2002's hybrid "shadow caster"): primary visibility, then
// local shading with shadow rays only — every punctual light once, exactly as Whitted mode does
// (punctual_shadow_ray), and the area lights with settings.shadow_samples stratified samples per
// pixel (soft shadows). No secondary rays: mirrors and glass show their diffuse part and emission.
// Every shadow ray of a tile is traced in one batch.

#include "specula/trace/area_lights.h"
#include "specula/trace/integrators.h"
#include "specula/trace/sampler.h"
#include "specula/trace/shading.h"

#include <algorithm>
#include <limits>
#include <numbers>

namespace specula::detail {
namespace {

/// The sampler set of the area-light samples: dimension 0 picks the triangle and, rescaled to its
/// interval of the CDF, places the point along with dimension 1. Dimensions (0, 1) of a pixel's
/// first 2^m samples form a (0,m,2)-net, so the light points of a pixel are stratified over the
/// CDF's order of triangles and within them: over the whole area for a light of a few triangles
/// (a quad), over rows of triangles for one of many (docs/design/shadow-caster.md).
constexpr std::uint32_t kAreaLightSet = 0;

/// A light point from one sample (sample_area_light, with the pick dimension reused).
AreaLightSample area_light_point(const EmitterTable& table, const vec3& p, const vec2& u) {
  const std::uint32_t k = table.pick(u.x);
  const EmitterTriangle& e = table.triangles()[k];
  const float below = e.cdf - e.pick;
  const float reused = std::clamp((u.x - below) / e.pick, 0.0f, 0x1.fffffep-1f);
  return sample_emitter_triangle(table, k, p, reused, u.y);
}

template <bool kAreaLights>
void shade_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& s,
                RayCounts& counts) {
  constexpr float kInvPi = std::numbers::inv_pi_v<float>;
  const SceneTables& tables = frame.tables;
  const TraceSettings& settings = frame.settings;
  const PrimaryHits& primary = s.primary;
  GuideBuffers* guides = frame.guides;
  const std::uint32_t samples = kAreaLights ? settings.shadow_samples : 0u;
  const float inv_samples = samples > 0 ? 1.0f / float(samples) : 0.0f;
  counts[RayKind::Primary] += primary.size();
  s.shadow_rays.clear();
  s.shadow_node.clear(); // here: the image index of the pixel a shadow ray serves
  s.shadow_value.clear();

  // Emission (or background) into the pixels, and every shadow ray into one batch.
  std::size_t i = 0;
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    const std::size_t k = i++;
    const std::uint32_t pixel = y * frame.width + x;
    const Hit hit = primary.hit(k);
    if (!hit.hit()) {
      frame.pixels[pixel] = settings.background;
      if (guides != nullptr) write_guide(*guides, pixel, nullptr);
      return;
    }
    const gpu::GpuMaterial& m = tables.materials[tables.instances[hit.instance].material];
    const ShadingPoint sp = shading_point(tables, hit, primary.direction(k), true);
    frame.pixels[pixel] = m.emission;
    const float diffuse = diffuse_weight(m);
    if (guides != nullptr) write_guide(*guides, pixel, &m, sp.shading_normal, hit.t);
    if (!(diffuse > 0.0f)) return;
    const vec3 albedo = m.base_color * (diffuse * kInvPi);
    const vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
    for (const gpu::GpuLight& light : tables.lights) {
      const std::optional<PunctualShadowRay> shadow =
          punctual_shadow_ray(light, sp, origin, albedo);
      if (!shadow) continue;
      s.shadow_rays.push_back(shadow->ray);
      s.shadow_node.push_back(pixel);
      s.shadow_value.push_back(shadow->value);
    }
    if constexpr (kAreaLights) {
      const PixelSampler sampler(pixel, settings.seed);
      for (std::uint32_t j = 0; j < samples; ++j) {
        const vec2 u = sampler.get2(settings.sample_offset + j, kAreaLightSet);
        // Sampled from the shadow ray's own origin, so that the sample's direction and distance
        // are the ray's (one normalisation, not two); the density is the solid angle there.
        const AreaLightSample ls = area_light_point(*frame.emitters, origin, u);
        if (!(ls.pdf > 0.0f)) continue;
        if (glm::dot(ls.to_light, sp.geometric_normal) <= 0.0f) continue; // behind the surface
        const float cos_theta = glm::dot(ls.to_light, sp.shading_normal);
        if (cos_theta <= 0.0f) continue;
        // Aimed at the light point itself and stopped just short of it, so that the emitting
        // triangle never shadows its own sample.
        s.shadow_rays.push_back(Ray{origin, 0.0f, ls.to_light, ls.distance * (1.0f - 1e-5f)});
        s.shadow_node.push_back(pixel);
        s.shadow_value.push_back(albedo * ls.emission * (cos_theta / ls.pdf * inv_samples));
      }
    }
  });

  // One batch; what is not blocked is added in emission order (lights in table order, then the
  // area samples in sample order), so a pixel's sum never depends on the tile.
  s.blocked.resize(s.shadow_rays.size());
  if (settings.shadows && !s.shadow_rays.empty()) {
    counts[RayKind::Shadow] += s.shadow_rays.size();
    frame.tracer.occluded_coherent(s.shadow_rays, s.blocked);
  } else {
    std::fill(s.blocked.begin(), s.blocked.end(), std::uint8_t{0});
  }
  for (std::size_t r = 0; r < s.shadow_rays.size(); ++r)
    if (s.blocked[r] == 0) frame.pixels[s.shadow_node[r]] += s.shadow_value[r];
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    vec3& p = frame.pixels[y * frame.width + x];
    p = finite_or_counted(p, counts);
  });
  s.shadow_rays.clear();
  s.shadow_node.clear();
  s.shadow_value.clear();
}

} // namespace

void shadow_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
                 RayCounts& counts) {
  // Specialised on the scene: without area lights the per-pixel sample loop does not exist.
  const bool area = frame.emitters != nullptr && frame.emitters->features().area_lights &&
                    frame.settings.shadow_samples > 0;
  if (area)
    shade_tile<true>(frame, tile, scratch, counts);
  else
    shade_tile<false>(frame, tile, scratch, counts);
}

} // namespace specula::detail
