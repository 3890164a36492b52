// The shadow caster (Purcell et al. 2002's hybrid "shadow caster"): primary visibility, then
// local shading with shadow rays only — every punctual light once, exactly as Whitted mode does
// (punctual_shadow_ray), and the area lights with settings.shadow_samples stratified samples per
// pixel (soft shadows). No secondary rays: mirrors and glass show their diffuse part and emission.
// A tile's shadow rays are traced in batches: each punctual light's, then each area-light
// sample's (the samples taken over all the tile's lit pixels at once: shadow_samples.h).

#include "specula/trace/integrators.h"
#include "specula/trace/sampler.h"
#include "specula/trace/shading.h"
#include "specula/trace/shading_batch.h"

#include <algorithm>
#include <limits>
#include <numbers>
#include <span>
#include <vector>

namespace specula::detail {
namespace {

/// The sampler set of the area-light samples: dimension 0 picks the triangle and, rescaled to its
/// interval of the CDF, places the point along with dimension 1. Dimensions (0, 1) of a pixel's
/// first 2^m samples form a (0,m,2)-net, so the light points of a pixel are stratified over the
/// CDF's order of triangles and within them: over the whole area for a light of a few triangles
/// (a quad), over rows of triangles for one of many (docs/design/shadow-caster.md).
constexpr std::uint32_t kAreaLightSet = 0;

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

  // The shadow rays by slot: one slot per punctual light (table order), then one for the
  // area-light sample being taken; slot k's rays are at [k · pixels, k · pixels + filled[k]), in
  // pixel order. A 16-wide packet then holds one slot of 16 neighbouring pixels (one light, or
  // one sample index towards the light), not the five rays of three pixels in turn. Each slot is
  // traced as one batch and what is not blocked is added: the punctual lights' slots in table
  // order, then the sample slot once per sample, so that every pixel sums its lights in table
  // order, then its area samples in sample order, and a pixel's sum never depends on the tile.
  const std::size_t pixels = primary.size();
  const std::size_t lights = tables.lights.size();
  const std::size_t slots = lights + (samples > 0 ? 1 : 0);
  s.shadow_rays.resize(pixels * slots);
  s.shadow_node.resize(pixels * slots); // here: the image index of the pixel a shadow ray serves
  s.shadow_value.resize(pixels * slots);
  s.blocked.resize(pixels * slots);
  std::vector<std::uint32_t>& filled = s.rays_of_pixel; // here: the rays of each slot
  filled.assign(slots, 0u);
  const auto emit = [&](std::size_t slot, const vec3& origin, const vec3& direction, float tfar,
                        std::uint32_t pixel, const vec3& value) {
    const std::size_t r = slot * pixels + filled[slot]++;
    store_ray(s.shadow_rays[r], origin, direction, tfar);
    s.shadow_node[r] = pixel;
    s.shadow_value[r] = value;
  };
  const auto trace_slot = [&](std::size_t slot) {
    const std::size_t first = slot * pixels, n = filled[slot];
    filled[slot] = 0;
    if (n == 0) return;
    const std::span<const Ray> rays(s.shadow_rays.data() + first, n);
    const std::span<std::uint8_t> blocked(s.blocked.data() + first, n);
    if (settings.shadows) {
      counts[RayKind::Shadow] += n;
      frame.tracer.occluded_coherent(rays, blocked);
    } else {
      std::fill(blocked.begin(), blocked.end(), std::uint8_t{0});
    }
    for (std::size_t r = first; r < first + n; ++r)
      if (s.blocked[r] == 0) frame.pixels[s.shadow_node[r]] += s.shadow_value[r];
  };

  // The shading points of the tile's hits at once (shading_batch.h).
  s.hits.resize(pixels);
  for (std::size_t k = 0; k < pixels; ++k) s.hits[k] = primary.hit(k);
  s.points.resize(pixels);
  if (pixels > 0)
    shading_points(tables, s.hits,
                   Directions{primary.dir_x.data(), primary.dir_y.data(), primary.dir_z.data(), 1},
                   s.points);

  // Emission (or background) into the pixels, the punctual lights' shadow rays into their slots,
  // and each lit pixel's surface for its area-light samples.
  s.surfaces.clear();
  std::size_t i = 0;
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    const std::size_t k = i++;
    const std::uint32_t pixel = y * frame.width + x;
    const Hit& hit = s.hits[k];
    if (!hit.hit()) {
      frame.pixels[pixel] = settings.background;
      if (guides != nullptr) write_guide(*guides, pixel, nullptr);
      return;
    }
    const gpu::GpuMaterial& m = tables.materials[tables.instances[hit.instance].material];
    const ShadingPoint& sp = s.points[k];
    frame.pixels[pixel] = m.emission;
    const float diffuse = diffuse_weight(m);
    if (guides != nullptr) write_guide(*guides, pixel, &m, sp.shading_normal, hit.t);
    if (!(diffuse > 0.0f)) return;
    const vec3 albedo = m.base_color * (diffuse * kInvPi);
    const vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
    for (std::size_t l = 0; l < lights; ++l)
      punctual_shadow_ray(tables.lights[l], sp, origin, albedo,
                          [&](const vec3& direction, float tfar, const vec3& value) {
                            emit(l, origin, direction, tfar, pixel, value);
                          });
    if constexpr (kAreaLights)
      s.surfaces.push(origin, sp.geometric_normal, sp.shading_normal, albedo, pixel,
                      PixelSampler(pixel, settings.seed).stream2(kAreaLightSet));
  });

  for (std::size_t slot = 0; slot < lights; ++slot) trace_slot(slot);

  // The area-light samples: sample after sample, every lit pixel's at once (eight at a time where
  // the CPU has AVX2), their shadow rays into the sample slot, traced.
  if constexpr (kAreaLights) {
    const ShadowSurfaces& lit = s.surfaces;
    const ShadowLightRays& out = s.light_rays;
    for (std::uint32_t j = 0; j < samples; ++j) {
      shadow_light_rays(*frame.emitters, lit, settings.sample_offset + j, inv_samples,
                        s.light_rays);
      for (std::size_t n = 0; n < lit.size(); ++n)
        if (out.valid[n] != 0)
          emit(lights, vec3(lit.ox[n], lit.oy[n], lit.oz[n]), vec3(out.dx[n], out.dy[n], out.dz[n]),
               out.tfar[n], lit.pixel[n], vec3(out.vr[n], out.vg[n], out.vb[n]));
      trace_slot(lights);
    }
  }
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    vec3& p = frame.pixels[y * frame.width + x];
    p = finite_or_counted(p, counts);
  });
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
