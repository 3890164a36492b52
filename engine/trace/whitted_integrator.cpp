// Whitted ray tracing (Whitted 1980) in waves (Purcell et al. 2002): shading a wave of hits emits
// shadow rays and reflection/refraction rays into batches; the backend traces each batch; the
// next wave is shaded, until no ray is left. Each ray of the tree keeps its own radiance, so what
// a ray leaving an object brings back exists as a value (delivered to the leaving-radiance hook).

#include "specula/trace/integrators.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"

#include <algorithm>
#include <limits>
#include <numbers>

namespace specula::detail {
namespace {

class WhittedTile {
public:
  WhittedTile(const FrameInputs& frame, TileScratch& s, RayCounts& counts)
      : frame_(frame), tables_(frame.tables), settings_(frame.settings), s_(s), counts_(counts) {}

  void run(const PacketTile& tile) {
    const PrimaryHits& primary = s_.primary;
    const std::size_t n = primary.size();
    s_.nodes.resize(n);
    s_.next_wave.clear();
    s_.shadow_rays.clear();
    s_.shadow_node.clear();
    s_.shadow_value.clear();
    s_.rays_of_pixel.assign(n, 0);
    std::size_t i = 0;
    tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
      WhittedNode& node = s_.nodes[i];
      node.radiance = vec3(0.0f);
      node.weight = vec3(1.0f);
      node.throughput = vec3(1.0f);
      node.ray = Ray{frame_.camera.origin, 0.0f, primary.direction(i),
                     std::numeric_limits<float>::infinity()};
      node.parent = kNoInstance;
      node.pixel = y * frame_.width + x;
      node.tile_pixel = std::uint32_t(i);
      node.depth = 0;
      node.from = kNoInstance;
      node.kind = RayKind::Primary;
      ++i;
    });
    counts_[RayKind::Primary] += n;

    // Wave 0: the primary hits, as the backend traced them.
    for (std::uint32_t k = 0; k < n; ++k) shade(k, primary.hit(k));
    trace_shadows();
    // Later waves: the reflection and refraction rays the previous wave spawned.
    while (!s_.next_wave.empty()) {
      s_.wave.swap(s_.next_wave);
      s_.next_wave.clear();
      s_.rays.resize(s_.wave.size());
      s_.hits.resize(s_.wave.size());
      for (std::size_t k = 0; k < s_.wave.size(); ++k) {
        const WhittedNode& node = s_.nodes[s_.wave[k]];
        s_.rays[k] = node.ray;
        ++counts_[node.kind];
      }
      frame_.tracer.intersect(s_.rays, s_.hits);
      for (std::size_t k = 0; k < s_.wave.size(); ++k) shade(s_.wave[k], s_.hits[k]);
      trace_shadows();
    }

    // Children were created after their parents: walking backwards folds every subtree into its
    // root (a pixel's children in a fixed order, so the sum is the same whatever the tile).
    for (std::size_t k = s_.nodes.size(); k-- > n;) {
      const WhittedNode& node = s_.nodes[k];
      s_.nodes[node.parent].radiance += node.weight * node.radiance;
    }
    if (frame_.hook != nullptr && s_.nodes.size() > n) deliver_leaving(n);
    for (std::size_t k = 0; k < n; ++k) frame_.pixels[s_.nodes[k].pixel] = s_.nodes[k].radiance;
  }

private:
  /// Local shading at a hit: emission, and a shadow ray towards every light that can light the
  /// diffuse part; then, below the depth limit, the reflection and refraction rays it spawns.
  void shade(std::uint32_t index, const Hit& hit) {
    constexpr float kInvPi = std::numbers::inv_pi_v<float>;
    // Copies: spawning rays appends to s_.nodes, which may move it.
    const WhittedNode node = s_.nodes[index];
    if (!hit.hit()) {
      s_.nodes[index].radiance = settings_.background;
      return;
    }
    const gpu::GpuMaterial& m = tables_.materials[tables_.instances[hit.instance].material];
    const vec3 d = node.ray.direction;
    const ShadingPoint sp = shading_point(tables_, hit, d, true);
    s_.nodes[index].radiance = m.emission;

    const float diffuse = std::max(0.0f, 1.0f - m.reflectivity - m.transmission);
    if (diffuse > 0.0f && !tables_.lights.empty()) {
      const vec3 albedo = m.base_color * (diffuse * kInvPi);
      const vec3 origin = offset_ray_origin(sp.position, sp.position_error, sp.geometric_normal);
      for (const gpu::GpuLight& light : tables_.lights) {
        const LightSample ls = sample_light(light, sp.position);
        if (glm::dot(ls.to_light, sp.geometric_normal) <= 0.0f) continue; // behind the surface
        const float cos_theta = glm::dot(ls.to_light, sp.shading_normal);
        if (cos_theta <= 0.0f || max_component(ls.irradiance) <= 0.0f) continue;
        // Stop just short of the light: a light placed on a surface must not shadow itself.
        const float tfar = std::isinf(ls.distance)
                               ? ls.distance
                               : glm::length(light.position - origin) * (1.0f - 1e-5f);
        s_.shadow_rays.push_back(Ray{origin, 0.0f, ls.to_light, tfar});
        s_.shadow_node.push_back(index);
        s_.shadow_value.push_back(albedo * ls.irradiance * cos_theta);
      }
    }
    if (node.depth >= settings_.max_depth) return;

    const SpecularSplit split = split_specular(m, sp, d);
    if (split.reflect_weight > 0.0f)
      spawn(node, index, hit.instance,
            offset_ray_origin(sp.position, sp.position_error, sp.geometric_normal),
            split.reflect_direction, split.reflect_weight, RayKind::Reflection);
    if (split.refract_weight > 0.0f)
      spawn(node, index, hit.instance,
            offset_ray_origin(sp.position, sp.position_error, -sp.geometric_normal),
            split.refract_direction, split.refract_weight, RayKind::Refraction);
  }

  void spawn(const WhittedNode& parent, std::uint32_t parent_index, std::uint32_t instance,
             const vec3& origin, const vec3& direction, float weight, RayKind kind) {
    const vec3 throughput = parent.throughput * weight;
    if (max_component(throughput) < settings_.min_weight) return;
    std::uint32_t& budget = s_.rays_of_pixel[parent.tile_pixel];
    if (budget >= kMaxRaysPerPixel) {
      ++counts_.dropped;
      return;
    }
    ++budget;
    WhittedNode child;
    child.radiance = vec3(0.0f);
    child.weight = vec3(weight);
    child.throughput = throughput;
    child.ray = Ray{origin, 0.0f, direction, std::numeric_limits<float>::infinity()};
    child.parent = parent_index;
    child.pixel = parent.pixel;
    child.tile_pixel = parent.tile_pixel;
    child.depth = parent.depth + 1;
    child.from = instance;
    child.kind = kind;
    s_.next_wave.push_back(std::uint32_t(s_.nodes.size()));
    s_.nodes.push_back(child);
  }

  void trace_shadows() {
    if (s_.shadow_rays.empty()) return;
    s_.blocked.resize(s_.shadow_rays.size());
    if (settings_.shadows) {
      counts_[RayKind::Shadow] += s_.shadow_rays.size();
      frame_.tracer.occluded(s_.shadow_rays, s_.blocked);
    } else {
      std::fill(s_.blocked.begin(), s_.blocked.end(), std::uint8_t{0});
    }
    // In emission order: a ray's lights are added in light order.
    for (std::size_t k = 0; k < s_.shadow_rays.size(); ++k)
      if (s_.blocked[k] == 0) s_.nodes[s_.shadow_node[k]].radiance += s_.shadow_value[k];
    s_.shadow_rays.clear();
    s_.shadow_node.clear();
    s_.shadow_value.clear();
  }

  void deliver_leaving(std::size_t first) {
    s_.leaving.clear();
    for (std::size_t k = first; k < s_.nodes.size(); ++k) {
      const WhittedNode& node = s_.nodes[k];
      LeavingRadiance r;
      r.from = tables_.entity(node.from);
      r.instance = node.from;
      r.kind = node.kind;
      r.depth = node.depth;
      r.pixel = node.pixel;
      r.origin = node.ray.origin;
      r.direction = node.ray.direction;
      r.weight = node.weight;
      r.throughput = node.throughput;
      r.radiance = node.radiance;
      s_.leaving.push_back(r);
    }
    frame_.hook->leaving(s_.leaving);
  }

  const FrameInputs& frame_;
  const SceneTables& tables_;
  const TraceSettings& settings_;
  TileScratch& s_;
  RayCounts& counts_;
};

} // namespace

void whitted_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
                  RayCounts& counts) {
  WhittedTile(frame, scratch, counts).run(tile);
}

} // namespace specula::detail
