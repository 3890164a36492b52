// Cast mode: local shading of the primary hits, no shadow or secondary rays.

#include "specula/trace/integrators.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"

#include <numbers>

namespace specula::detail {

void cast_tile(const FrameInputs& frame, const PacketTile& tile, const PrimaryHits& hits,
               RayCounts& counts) {
  constexpr float kInvPi = std::numbers::inv_pi_v<float>;
  const SceneTables& tables = frame.tables;
  const std::span<const gpu::GpuLight> lights = tables.lights;
  counts[RayKind::Primary] += hits.size();
  std::size_t i = 0;
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    const std::size_t k = i++;
    vec3 radiance = frame.settings.background;
    if (hits.instance[k] != kNoInstance) {
      const Hit hit = hits.hit(k);
      const gpu::GpuMaterial& m = tables.materials[tables.instances[hit.instance].material];
      const ShadingPoint sp = shading_point(tables, hit, hits.direction(k), false);
      radiance = m.emission;
      const vec3 albedo = m.base_color * kInvPi;
      for (const gpu::GpuLight& light : lights) {
        const LightSample ls = sample_light(light, sp.position);
        if (glm::dot(ls.to_light, sp.geometric_normal) <= 0.0f) continue; // behind the surface
        const float cos_theta = glm::dot(ls.to_light, sp.shading_normal);
        if (cos_theta <= 0.0f || max_component(ls.irradiance) <= 0.0f) continue;
        radiance += albedo * ls.irradiance * cos_theta;
      }
    }
    frame.pixels[std::size_t(y) * frame.width + x] = radiance;
  });
}

} // namespace specula::detail
