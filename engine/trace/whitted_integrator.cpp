// Whitted ray tracing (Whitted 1980) in waves (Purcell et al. 2002): shading a wave of hits emits
// shadow rays and reflection/refraction rays into batches; the backend traces each batch; the
// next wave is shaded, until no ray is left. Each ray of the tree keeps its own radiance, so what
// a ray leaving an object brings back exists as a value (delivered to the leaving-radiance hook).

#include "specula/trace/integrators.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"
#include "specula/trace/shading_batch.h"

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
    begin(n);
    std::size_t i = 0;
    tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
      set_root(s_.nodes[i], frame_.camera.origin, 0.0f, primary.direction(i),
               std::numeric_limits<float>::infinity(), y * frame_.width + x, std::uint32_t(i), 0,
               RayKind::Primary);
      ++i;
    });
    counts_[RayKind::Primary] += n;

    // Wave 0: the primary hits, as the backend traced them; their directions are the roots'.
    if (n == 0) return;
    s_.hits.resize(n);
    for (std::uint32_t k = 0; k < n; ++k) s_.hits[k] = primary.hit(k);
    static_assert(sizeof(WhittedNode) % sizeof(float) == 0);
    shading_points(
        s_.hits,
        Directions::aos(reinterpret_cast<const float*>(s_.nodes.data()) +
                            (offsetof(WhittedNode, ray) + offsetof(Ray, direction)) / sizeof(float),
                        sizeof(WhittedNode) / sizeof(float)));
    for (std::uint32_t k = 0; k < n; ++k) shade(k, s_.hits[k], s_.points[k]);
    trace_shadows();
    trace_waves();
    fold(n);
    if (frame_.hook != nullptr && frame_.leaving && s_.nodes.size() > n) deliver_leaving(n);
    for (std::size_t k = 0; k < n; ++k)
      frame_.pixels[s_.nodes[k].pixel] = finite_or_counted(s_.nodes[k].radiance, counts_);
  }

  /// Trees rooted at arbitrary rays (whitted_rays).
  void run_rays(std::span<const Ray> rays, std::uint32_t depth, std::uint32_t skip,
                std::span<RadianceSample> out) {
    const std::size_t n = rays.size();
    begin(n);
    s_.rays.assign(rays.begin(), rays.end());
    s_.hits.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      set_root(s_.nodes[k], rays[k].origin, rays[k].tnear, rays[k].direction, rays[k].tfar,
               std::uint32_t(k), std::uint32_t(k), depth, RayKind::Reflection);
      s_.nodes[k].from = skip;
      ++counts_[RayKind::Reflection];
    }
    frame_.tracer.intersect(s_.rays, s_.hits);
    // Pass through the skipped instance: at most a few surfaces of it lie on any ray.
    for (int pass = 0; pass < 8; ++pass) {
      s_.wave.clear();
      for (std::uint32_t k = 0; k < n; ++k)
        if (s_.hits[k].hit() && s_.hits[k].instance == skip) s_.wave.push_back(k);
      if (s_.wave.empty()) break;
      s_.shadow_rays.clear();
      for (const std::uint32_t k : s_.wave) {
        Ray r = rays[k];
        // Just past the skipped surface: backends may report a hit at exactly tnear again.
        r.tnear = s_.hits[k].t * (1.0f + 1e-5f) + 1e-7f;
        s_.shadow_rays.push_back(r);
      }
      s_.blocked.clear();
      std::vector<Hit> again(s_.wave.size());
      frame_.tracer.intersect(s_.shadow_rays, again);
      for (std::size_t j = 0; j < s_.wave.size(); ++j) {
        Hit h = again[j];
        if (pass == 7 && h.hit() && h.instance == skip) h = Hit{};
        s_.hits[s_.wave[j]] = h;
      }
      s_.shadow_rays.clear();
    }
    s_.wave.clear();
    ray_shading_points();
    for (std::uint32_t k = 0; k < n; ++k) shade(k, s_.hits[k], s_.points[k]);
    trace_shadows();
    trace_waves();
    fold(n);
    for (std::size_t k = 0; k < n; ++k) {
      const WhittedNode& node = s_.nodes[k];
      out[k] = RadianceSample{finite_or_counted(node.radiance, counts_), node.hit_t,
                              node.hit_entity, node.seen, node.rays};
    }
  }

private:
  /// The shading points of the hits s_.hits of the rays s_.rays, into s_.points (misses skipped).
  void ray_shading_points() {
    static_assert(sizeof(Ray) % sizeof(float) == 0 &&
                  offsetof(Ray, direction) % sizeof(float) == 0);
    if (s_.rays.empty()) return;
    shading_points(s_.hits, Directions::aos(reinterpret_cast<const float*>(s_.rays.data()) +
                                                offsetof(Ray, direction) / sizeof(float),
                                            sizeof(Ray) / sizeof(float)));
  }

  /// The shading points of `hits`, into s_.points (misses skipped).
  void shading_points(std::span<const Hit> hits, const Directions& directions) {
    s_.points.resize(hits.size());
    if (!hits.empty()) detail::shading_points(tables_, hits, directions, s_.points);
  }

  void begin(std::size_t n) {
    s_.nodes.resize(n);
    s_.next_wave.clear();
    s_.shadow_rays.clear();
    s_.shadow_node.clear();
    s_.shadow_value.clear();
    s_.rays_of_pixel.assign(n, 0);
  }

  /// Sets every field of `node` in place: a node built on the stack and copied into the array
  /// reads back with wide loads what narrow stores just wrote, and the stores cannot be forwarded
  /// to them (about 6% of a Whitted frame stalled there).
  static void set_root(WhittedNode& node, const vec3& origin, float tnear, const vec3& direction,
                       float tfar, std::uint32_t pixel, std::uint32_t tile_pixel,
                       std::uint32_t depth, RayKind kind) {
    node.radiance = vec3(0.0f);
    node.weight = vec3(1.0f);
    node.throughput = vec3(1.0f);
    node.ray.origin = origin;
    node.ray.tnear = tnear;
    node.ray.direction = direction;
    node.ray.tfar = tfar;
    node.parent = kNoInstance;
    node.pixel = pixel;
    node.tile_pixel = tile_pixel;
    node.depth = depth;
    node.from = kNoInstance;
    node.kind = kind;
    node.exits = false;
    node.answer = CacheAnswer::Trace;
    node.cached = vec3(0.0f);
    node.hit_t = std::numeric_limits<float>::infinity();
    node.hit_entity = kNoInstance;
    node.seen = 0;
    node.rays = kind == RayKind::Primary ? 0u : 1u;
  }

  /// The reflection and refraction rays the previous wave spawned, wave after wave, until none
  /// is left; rays leaving a cached object are first offered to the hook.
  void trace_waves() {
    while (!s_.next_wave.empty()) {
      s_.wave.swap(s_.next_wave);
      s_.next_wave.clear();
      if (frame_.lookups) serve_from_cache();
      if (s_.wave.empty()) continue;
      s_.rays.resize(s_.wave.size());
      s_.hits.resize(s_.wave.size());
      for (std::size_t k = 0; k < s_.wave.size(); ++k) {
        const WhittedNode& node = s_.nodes[s_.wave[k]];
        s_.rays[k] = node.ray;
        ++counts_[node.kind];
      }
      frame_.tracer.intersect(s_.rays, s_.hits);
      ray_shading_points();
      for (std::size_t k = 0; k < s_.wave.size(); ++k) shade(s_.wave[k], s_.hits[k], s_.points[k]);
      trace_shadows();
    }
  }

  /// Asks the hook about the wave's rays that exit an object; those it serves leave the wave
  /// with their radiance set (UseIfClear after an occlusion ray confirms nothing is in the way).
  void serve_from_cache() {
    s_.queries.clear();
    s_.query_node.clear();
    for (const std::uint32_t k : s_.wave) {
      const WhittedNode& node = s_.nodes[k];
      if (!node.exits) continue;
      s_.queries.push_back(
          LeavingQuery{node.from, node.pixel, node.depth, node.ray.origin, node.ray.direction});
      s_.query_node.push_back(k);
    }
    if (s_.queries.empty()) return;
    s_.answers.resize(s_.queries.size());
    frame_.hook->lookup(s_.queries, s_.answers);
    s_.confirm_rays.clear();
    s_.confirm_node.clear();
    for (std::size_t q = 0; q < s_.queries.size(); ++q) {
      WhittedNode& node = s_.nodes[s_.query_node[q]];
      const CachedRadiance& a = s_.answers[q];
      node.answer = a.answer;
      if (a.answer == CacheAnswer::Use) {
        node.radiance = a.radiance;
        node.seen = a.seen;
        node.rays = 0;
      } else if (a.answer == CacheAnswer::Verify) {
        node.cached = a.radiance;
      } else if (a.answer == CacheAnswer::UseIfClear) {
        node.radiance = a.radiance;
        node.seen = a.seen;
        s_.confirm_rays.push_back(Ray{node.ray.origin, 0.0f, node.ray.direction, a.clear_distance});
        s_.confirm_node.push_back(s_.query_node[q]);
      }
    }
    if (!s_.confirm_rays.empty()) {
      s_.confirm_blocked.resize(s_.confirm_rays.size());
      counts_[RayKind::Shadow] += s_.confirm_rays.size();
      frame_.tracer.occluded(s_.confirm_rays, s_.confirm_blocked);
      for (std::size_t c = 0; c < s_.confirm_rays.size(); ++c) {
        WhittedNode& node = s_.nodes[s_.confirm_node[c]];
        node.rays = 1; // the confirming ray
        if (s_.confirm_blocked[c] != 0) {
          node.rays = 2; // and the ray itself
          node.answer = CacheAnswer::Trace;
          node.radiance = vec3(0.0f);
          node.seen = 0;
        } else {
          node.answer = CacheAnswer::Use;
        }
      }
    }
    // The wave keeps what must still be traced, in order.
    std::size_t kept = 0;
    for (const std::uint32_t k : s_.wave)
      if (s_.nodes[k].answer != CacheAnswer::Use) s_.wave[kept++] = k;
    s_.wave.resize(kept);
  }

  /// Children were created after their parents: walking backwards folds every subtree into its
  /// root (a pixel's children in a fixed order, so the sum is the same whatever the tile).
  void fold(std::size_t roots) {
    for (std::size_t k = s_.nodes.size(); k-- > roots;) {
      const WhittedNode& node = s_.nodes[k];
      WhittedNode& parent = s_.nodes[node.parent];
      parent.radiance += node.weight * node.radiance;
      parent.seen |= node.seen;
      parent.rays += node.rays;
    }
  }

  /// Local shading at a hit: emission, and a shadow ray towards every light that can light the
  /// diffuse part; then, below the depth limit, the reflection and refraction rays it spawns.
  /// `sp`: the hit's shading point (computed for the whole wave).
  void shade(std::uint32_t index, const Hit& hit, const ShadingPoint& sp) {
    constexpr float kInvPi = std::numbers::inv_pi_v<float>;
    // Copies of what spawning needs (it appends to s_.nodes, which may move it): the parent's
    // fields, not the whole node, which was most of this function's reads.
    const WhittedNode& at = s_.nodes[index];
    const Parent node{at.throughput, at.pixel, at.tile_pixel, at.depth};
    const vec3 d = at.ray.direction;
    if (!hit.hit()) {
      s_.nodes[index].radiance = settings_.background;
      return;
    }
    s_.nodes[index].hit_t = hit.t;
    s_.nodes[index].hit_entity = tables_.instances[hit.instance].entity_index;
    s_.nodes[index].seen = entity_bit(s_.nodes[index].hit_entity);
    const gpu::GpuMaterial& m = tables_.materials[tables_.instances[hit.instance].material];
    s_.nodes[index].radiance = m.emission;

    const float diffuse = diffuse_weight(m);
    if (diffuse > 0.0f && !tables_.lights.empty()) {
      const vec3 albedo = m.base_color * (diffuse * kInvPi);
      const vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
      for (const gpu::GpuLight& light : tables_.lights)
        punctual_shadow_ray(light, sp, origin, albedo,
                            [&](const vec3& direction, float tfar, const vec3& value) {
                              store_ray(s_.shadow_rays.emplace_back(), origin, direction, tfar);
                              s_.shadow_node.push_back(index);
                              s_.shadow_value.push_back(value);
                            });
    }
    if (node.depth >= settings_.max_depth) return;

    const SpecularSplit split = split_specular(m, sp, d);
    if (split.reflect_weight > 0.0f)
      spawn(node, index, hit.instance,
            offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal),
            split.reflect_direction, split.reflect_weight, RayKind::Reflection, sp.front_face);
    if (split.refract_weight > 0.0f)
      spawn(node, index, hit.instance,
            offset_ray_origin(sp.spawn_point, sp.spawn_error, -sp.geometric_normal),
            split.refract_direction, split.refract_weight, RayKind::Refraction, !sp.front_face);
  }

  /// What a node's children take from it.
  struct Parent {
    vec3 throughput;
    std::uint32_t pixel, tile_pixel, depth;
  };

  void spawn(const Parent& parent, std::uint32_t parent_index, std::uint32_t instance,
             const vec3& origin, const vec3& direction, float weight, RayKind kind, bool exits) {
    const vec3 throughput = parent.throughput * weight;
    if (max_component(throughput) < settings_.min_weight) return;
    std::uint32_t& budget = s_.rays_of_pixel[parent.tile_pixel];
    if (budget >= kMaxRaysPerPixel) {
      ++counts_.dropped;
      return;
    }
    ++budget;
    s_.next_wave.push_back(std::uint32_t(s_.nodes.size()));
    WhittedNode& child = s_.nodes.emplace_back();
    set_root(child, origin, 0.0f, direction, std::numeric_limits<float>::infinity(), parent.pixel,
             parent.tile_pixel, parent.depth + 1, kind);
    child.weight = vec3(weight);
    child.throughput = throughput;
    child.parent = parent_index;
    child.from = instance;
    child.exits = exits;
  }

  void trace_shadows() {
    if (s_.shadow_rays.empty()) return;
    s_.blocked.resize(s_.shadow_rays.size());
    if (settings_.shadows) {
      counts_[RayKind::Shadow] += s_.shadow_rays.size();
      frame_.tracer.occluded_coherent(s_.shadow_rays, s_.blocked);
      for (const std::uint32_t node : s_.shadow_node) ++s_.nodes[node].rays;
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
      r.exits = node.exits;
      r.answer = node.answer;
      r.depth = node.depth;
      r.pixel = node.pixel;
      r.origin = node.ray.origin;
      r.direction = node.ray.direction;
      r.weight = node.weight;
      r.throughput = node.throughput;
      r.radiance = node.radiance;
      r.cached = node.cached;
      r.hit_t = node.hit_t;
      r.hit_entity = node.hit_entity;
      r.seen = node.seen;
      r.rays = node.rays;
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

void whitted_rays(const FrameInputs& frame, std::span<const Ray> rays, std::uint32_t depth,
                  std::uint32_t skip, TileScratch& scratch, RayCounts& counts,
                  std::span<RadianceSample> out) {
  FrameInputs inputs = frame;
  inputs.hook = nullptr;
  inputs.lookups = false;
  WhittedTile(inputs, scratch, counts).run_rays(rays, depth, skip, out);
}

} // namespace specula::detail
