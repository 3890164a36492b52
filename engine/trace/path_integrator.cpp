// Unidirectional path tracing (Kajiya 1986) in waves (Purcell et al. 2002): every live path of a
// tile is one entry of compact arrays; a wave traces all their rays in one intersect call, shades
// the hits, batches the next-event shadow rays of the whole wave into one occluded call, and
// compacts the survivors into the next wave. Direct lighting mixes light and BSDF sampling with
// the power heuristic (Veach & Guibas 1995); paths end by Russian roulette or at the depth limit.
// docs/design/path-tracing.md describes the estimator.
//
// With a radiance hook (ray-cache cubes), a ray that leaves an object outwards is first offered to
// the hook, which may serve it from its cache: the path then ends with the cached radiance. A
// traced one opens a leaving record that collects every later contribution to its sample, so at
// the end of the batch its radiance — the rest of the path divided by its throughput, a
// one-sample estimate — goes to the hook (docs/design/ray-cache.md, "Path mode").

#include "specula/trace/area_lights.h"
#include "specula/trace/integrators.h"
#include "specula/trace/sample_batch.h"
#include "specula/trace/sampler.h"
#include "specula/trace/shading.h"
#include "specula/trace/shading_batch.h"
#include "specula/trace/vertex_starts.h"

#include <algorithm>
#include <array>
#include <limits>
#include <numbers>
#include <utility>

namespace specula::detail {
namespace {

constexpr float kInvPi = std::numbers::inv_pi_v<float>;

/// Most paths one wave holds: a tile's pixels × spp are run in sample batches of at most this
/// many paths, which bounds the scratch memory whatever --spp asks.
constexpr std::size_t kMaxPathsPerBatch = 8192;

/// Most punctual lights whose samples a wave computes ahead (vertex_starts.h).
constexpr std::size_t kMostBatchedLights = 8;

/// Vertices from this depth on (0: the primary hit) continue only by Russian roulette.
constexpr std::uint32_t kRouletteDepth = 3;

/// Sample sets (sampler.h) per vertex: the lobe choice and direction, the area-light sample, the
/// roulette decision.
constexpr std::uint32_t kSetsPerVertex = 3;
constexpr std::uint32_t kSetBsdf = 0, kSetLight = 1, kSetRoulette = 2;

/// A unit vector's orthonormal basis (Duff et al., "Building an Orthonormal Basis, Revisited",
/// JCGT 2017): branch-free and continuous except at the sign flip.
void orthonormal_basis(const vec3& n, vec3& t, vec3& b) {
  const float sign = std::copysign(1.0f, n.z);
  const float a = -1.0f / (sign + n.z);
  const float c = n.x * n.y * a;
  t = vec3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  b = vec3(c, sign + n.y * n.y * a, -n.y);
}

/// A cosine-distributed direction about unit n from two uniform numbers (Malley's method).
vec3 cosine_direction(const vec3& n, float u1, float u2) {
  const float r = std::sqrt(u1);
  const float phi = 2.0f * std::numbers::pi_v<float> * u2;
  const float x = r * std::cos(phi), y = r * std::sin(phi);
  const float z = std::sqrt(std::max(0.0f, 1.0f - u1));
  vec3 t, b;
  orthonormal_basis(n, t, b);
  return glm::normalize(x * t + y * b + z * n);
}

/// The scene's features as template parameters: a loop instantiated without dielectrics or area
/// lights has no branch for them.
template <bool kArea, bool kPunctual, bool kMirror, bool kDielectric>
class PathTile {
public:
  PathTile(const FrameInputs& frame, TileScratch& s, RayCounts& counts)
      : frame_(frame), tables_(frame.tables), settings_(frame.settings), w_(s.path),
        primary_(s.primary), counts_(counts), emitters_(*frame.emitters),
        hook_(frame.leaving ? frame.hook : nullptr) {}

  void run(const PacketTile& tile) {
    const std::size_t n = primary_.size();
    w_.pixel.clear();
    tile.for_each_pixel(
        [&](std::uint32_t x, std::uint32_t y) { w_.pixel.push_back(y * frame_.width + x); });
    counts_[RayKind::Primary] += n;
    // The primary hits and their shading points, once for every batch of the tile.
    w_.primary_hits.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) w_.primary_hits[i] = primary_.hit(i);
    w_.primary_points.resize(n);
    if (n > 0)
      detail::shading_points(
          tables_, w_.primary_hits,
          Directions{primary_.dir_x.data(), primary_.dir_y.data(), primary_.dir_z.data(), 1},
          w_.primary_points);
    if (frame_.guides != nullptr) write_guides();

    const std::uint32_t spp = std::max(1u, settings_.spp);
    w_.sum.assign(n, vec3(0.0f));
    const std::uint32_t batch = std::uint32_t(
        std::clamp<std::size_t>(kMaxPathsPerBatch / std::max<std::size_t>(n, 1), 1, spp));
    for (std::uint32_t first = 0; first < spp; first += batch)
      run_batch(first, std::min(batch, spp - first));
    const float inv_spp = 1.0f / float(spp);
    for (std::size_t i = 0; i < n; ++i)
      frame_.pixels[w_.pixel[i]] = spp == 1 ? w_.sum[i] : w_.sum[i] * inv_spp;
  }

private:
  /// Samples [first, first + count) of every pixel: path (i, s) owns radiance slot i·count + s,
  /// so each sample sums its own contributions in its own order, whatever else is in the wave.
  void run_batch(std::uint32_t first, std::uint32_t count) {
    const std::size_t n = primary_.size();
    w_.radiance.assign(n * count, vec3(0.0f));
    w_.paths.clear();
    w_.rays.clear();
    w_.records.clear();
    w_.exits.clear();
    // Wave 0: the primary hits, shaded once per pixel and continued by each of its samples.
    w_.hit_paths.clear();
    for (std::uint32_t i = 0; i < n; ++i) {
      const std::uint32_t stream = PixelSampler(w_.pixel[i], settings_.seed).stream_seed();
      for (std::uint32_t s = 0; s < count; ++s) {
        Path p;
        p.throughput = vec3(1.0f);
        p.bsdf_pdf = 0.0f;
        p.previous = vec3(0.0f);
        p.slot = i * count + s;
        p.pixel = w_.pixel[i];
        p.stream = stream;
        p.sample = settings_.sample_offset + first + s;
        p.leaving = kNoInstance;
        w_.hit_paths.push_back(p);
      }
    }
    draw_samples(w_.hit_paths, 0);
    starts(w_.primary_hits, w_.primary_points, count, w_.hit_paths.size(), 0);
    for (std::uint32_t i = 0; i < n; ++i)
      shade_pixel(w_.primary_hits[i], primary_.direction(i), w_.primary_points[i], i * count,
                  count);
    trace_shadows(true);
    for (std::uint32_t depth = 1; !w_.paths.empty(); ++depth) {
      w_.wave_paths.swap(w_.paths);
      w_.wave_rays.swap(w_.rays);
      w_.wave_exits.swap(w_.exits);
      w_.paths.clear();
      w_.rays.clear();
      w_.exits.clear();
      if (hook_ != nullptr) {
        open_leaving(depth);
        for (const Path& p : w_.wave_paths) count_ray(p.leaving);
      }
      w_.hits.resize(w_.wave_rays.size());
      frame_.tracer.intersect(w_.wave_rays, w_.hits);
      if (hook_ != nullptr) {
        for (std::size_t k = 0; k < w_.wave_paths.size(); ++k)
          note_hit(w_.wave_paths[k].leaving, w_.hits[k]);
        look_up_leaving(depth);
      }
      draw_samples(w_.wave_paths, depth);
      static_assert(sizeof(Ray) % sizeof(float) == 0 &&
                    offsetof(Ray, direction) % sizeof(float) == 0);
      shading_points(w_.hits, Directions::aos(reinterpret_cast<const float*>(w_.wave_rays.data()) +
                                                  offsetof(Ray, direction) / sizeof(float),
                                              sizeof(Ray) / sizeof(float)));
      starts(w_.hits, w_.points, 1, w_.wave_paths.size(), depth);
      for (std::size_t k = 0; k < w_.wave_paths.size(); ++k) {
        const std::uint32_t e = hook_ != nullptr ? w_.exit_of[k] : kNoInstance;
        const Hit& hit = w_.hits[k];
        const vec3& d = w_.wave_rays[k].direction;
        if (e == kNoInstance)
          shade(w_.wave_paths[k], w_.samples[k], hit, d, w_.points[k], k, depth);
        else
          shade_leaving(w_.wave_paths[k], w_.samples[k], hit, d, w_.points[k], k, depth);
      }
      trace_shadows(false);
    }
    if (hook_ != nullptr) deliver_leaving();
    for (std::uint32_t i = 0; i < n; ++i)
      for (std::uint32_t s = 0; s < count; ++s)
        w_.sum[i] += finite_or_counted(w_.radiance[i * count + s], counts_);
  }

  /// The denoiser's guides from the primary hits and their shading points.
  void write_guides() {
    GuideBuffers& g = *frame_.guides;
    for (std::uint32_t i = 0; i < primary_.size(); ++i) {
      const std::uint32_t pixel = w_.pixel[i];
      const Hit& hit = w_.primary_hits[i];
      if (!hit.hit()) {
        write_guide(g, pixel, nullptr);
        continue;
      }
      write_guide(g, pixel, &material(hit), w_.primary_points[i].shading_normal, hit.t);
    }
  }

  [[nodiscard]] const gpu::GpuMaterial& material(const Hit& hit) const {
    return tables_.materials[tables_.instances[hit.instance].material];
  }

  /// The sample dimensions the vertices of a wave's paths may use (VertexSamples), for the whole
  /// wave at once: only the sets and dimensions this scene's vertices at `depth` can read.
  void draw_samples(const std::vector<Path>& paths, std::uint32_t depth) {
    w_.samples.resize(paths.size());
    if (paths.empty() || depth >= settings_.max_depth) return; // the last vertex draws none
    static_assert(sizeof(Path) % sizeof(std::uint32_t) == 0 &&
                  sizeof(VertexSamples) % sizeof(float) == 0);
    const SampleKeys keys{&paths[0].stream, &paths[0].sample, sizeof(Path) / sizeof(std::uint32_t),
                          paths.size()};
    constexpr std::size_t kStride = sizeof(VertexSamples) / sizeof(float);
    VertexSamples& first = w_.samples[0];
    const std::uint32_t set = depth * kSetsPerVertex;
    std::array<SampleRequest, 3> requests;
    std::size_t count = 0;
    if (kArea && settings_.sampling != LightSampling::Bsdf)
      requests[count++] = {set + kSetLight, 0b0111u, first.light};
    // Dimension 0 picks a lobe only where a material has a specular one, 1 chooses between
    // reflection and refraction only with dielectrics.
    requests[count++] = {set + kSetBsdf,
                         0b1100u | (kMirror || kDielectric ? 0b0001u : 0u) |
                             (kDielectric ? 0b0010u : 0u),
                         first.bsdf};
    if (depth >= kRouletteDepth) requests[count++] = {set + kSetRoulette, 0b0001u, &first.roulette};
    draw_sample_dims(keys, std::span(requests.data(), count), kStride);
  }

  /// What the wave's vertices start from (vertex_starts.h), into w_.starts: vertex k is hit
  /// k / per_point; area-light samples where this depth samples lights.
  void starts(std::span<const Hit> hits, std::span<const ShadingPoint> points,
              std::size_t per_point, std::size_t count, std::uint32_t depth) {
    VertexInputs in;
    in.hits = hits;
    in.points = points;
    in.per_point = per_point;
    in.count = count;
    if (kPunctual && batched_lights()) in.lights = tables_.lights;
    if (kArea && settings_.sampling != LightSampling::Bsdf && depth < settings_.max_depth &&
        count > 0) {
      static_assert(offsetof(VertexSamples, light) == 0 &&
                    sizeof(VertexSamples) % sizeof(float) == 0);
      in.emitters = &emitters_;
      in.light_u = w_.samples[0].light;
      in.stride = sizeof(VertexSamples) / sizeof(float);
    }
    vertex_starts(in, w_.starts);
  }

  /// Whether the wave's vertex starts hold the punctual lights' samples (seven floats per light
  /// and vertex): only for a few lights, so that a scene with thousands of them does not make the
  /// wave's scratch thousands of times larger; beyond that each vertex samples them as it shades.
  [[nodiscard]] bool batched_lights() const { return tables_.lights.size() <= kMostBatchedLights; }

  /// The shading points of a wave's hits (misses skipped), into w_.points.
  void shading_points(std::span<const Hit> hits, const Directions& directions) {
    w_.points.resize(hits.size());
    if (!hits.empty()) detail::shading_points(tables_, hits, directions, w_.points);
  }

  /// The primary hit of one pixel (its shading point `sp`) for its `count` paths
  /// w_.hit_paths[first …].
  void shade_pixel(const Hit& hit, const vec3& d, const ShadingPoint& sp, std::uint32_t first,
                   std::uint32_t count) {
    if (!hit.hit()) {
      for (std::uint32_t s = first; s < first + count; ++s) {
        const Path& p = w_.hit_paths[s];
        contribute(p.slot, p.leaving, p.throughput * settings_.background);
      }
      return;
    }
    for (std::uint32_t s = first; s < first + count; ++s)
      shade_vertex(w_.hit_paths[s], w_.samples[s], vertex(hit, sp, s), d, 0);
  }

  void shade(const Path& p, const VertexSamples& u, const Hit& hit, const vec3& d,
             const ShadingPoint& sp, std::size_t k, std::uint32_t depth) {
    if (!hit.hit()) {
      contribute(p.slot, p.leaving, p.throughput * settings_.background);
      return;
    }
    shade_vertex(p, u, vertex(hit, sp, k), d, depth);
  }

  /// The first hit of a ray that left a cached object (its record is p.leaving), as the hook
  /// answered for it: traced on (its emission noted, so the record's radiance can leave it out);
  /// served (the sample takes emission + the cached radiance, the path ends); or refreshed (the
  /// sample takes the same, and the path goes on for the record alone).
  void shade_leaving(Path& p, const VertexSamples& u, const Hit& hit, const vec3& d,
                     const ShadingPoint& sp, std::size_t k, std::uint32_t depth) {
    PathLeaving& rec = w_.records[p.leaving];
    const CacheAnswer answer = rec.ray.answer;
    if (!hit.hit() || answer == CacheAnswer::Trace) {
      if (!hit.hit()) {
        contribute(p.slot, p.leaving, p.throughput * settings_.background);
        return;
      }
      shade_vertex(p, u, vertex(hit, sp, k), d, depth, p.leaving);
      return;
    }
    const Vertex v = vertex(hit, sp, k);
    // The leaving ray is specular (no light-sampling strategy reaches its hit): its emission
    // counts fully.
    vec3 emitted(0.0f);
    if constexpr (kArea) emitted = v.m->emission;
    const std::uint32_t parent = rec.parent;
    contribute(p.slot, parent, p.throughput * (emitted + rec.ray.cached));
    // The enclosing records saw what the cached value saw (invalidation follows it).
    for (std::uint32_t c = parent; c != kNoInstance; c = w_.records[c].parent)
      w_.records[c].ray.seen |= rec.ray.seen;
    if (answer != CacheAnswer::Refresh) return; // served: the path ends here
    // Refreshed: what the path gathers from here on is the record's alone.
    rec.parent = kNoInstance;
    p.slot = kDetached;
    shade_vertex(p, u, v, d, depth, kNoInstance, false);
  }

  /// What a hit's shading needs: its shading point and starts (computed for the whole wave) and
  /// material.
  struct Vertex {
    const ShadingPoint& sp; ///< computed for the whole wave (shading_points)
    const gpu::GpuMaterial* m;
    std::uint32_t instance, primitive;
    std::size_t start; ///< its entry of w_.starts
  };

  [[nodiscard]] Vertex vertex(const Hit& hit, const ShadingPoint& sp, std::size_t k) const {
    return Vertex{sp, &material(hit), hit.instance, hit.primitive, k};
  }

  /// Emission (weighted against light sampling where the ray was BSDF-sampled at a diffuse
  /// vertex), next-event estimation of every light at the diffuse part, then, below the depth
  /// limit, the sampled continuation. `first_of`: the leaving record whose first hit this is
  /// (its emission is noted apart); `emission` false when the caller has counted it.
  /// `u`: the path's samples at this vertex (draw_samples).
  [[gnu::flatten]] void shade_vertex(const Path& p, const VertexSamples& u, const Vertex& v,
                                     const vec3& d, std::uint32_t depth,
                                     std::uint32_t first_of = kNoInstance, bool emission = true) {
    const gpu::GpuMaterial& m = *v.m;
    const ShadingPoint& sp = v.sp;
    if constexpr (kArea) {
      if (emission && m.emission != vec3(0.0f)) {
        float weight = 1.0f;
        // bsdf_pdf 0: seen by the camera or through a specular bounce, which light sampling
        // cannot reach.
        if (p.bsdf_pdf > 0.0f) {
          if (settings_.sampling == LightSampling::Light) {
            weight = 0.0f;
          } else if (settings_.sampling == LightSampling::Mis) {
            const std::uint32_t e = emitters_.find(v.instance, v.primitive);
            if (e != EmitterTable::kNone)
              weight = power_heuristic(
                  p.bsdf_pdf, area_light_pdf(emitters_.triangles()[e], p.previous, sp.position));
          }
        }
        if (weight > 0.0f) {
          contribute(p.slot, p.leaving, p.throughput * m.emission * weight);
          if (first_of != kNoInstance)
            w_.records[first_of].emitted += p.throughput * m.emission * weight;
        }
      }
    }

    const float diffuse = diffuse_weight(m);
    const float specular =
        (kMirror ? m.reflectivity : 0.0f) + (kDielectric ? m.transmission : 0.0f);
    const float total = diffuse + specular;
    // Probability of the diffuse lobe: with it, the mixture's density of a direction.
    const float p_diffuse = total > 0.0f ? diffuse / total : 0.0f;
    const bool last = depth >= settings_.max_depth;
    // A cached object's own probe of incoming light may light its diffuse lobe (ray-cache
    // cubes in path mode: RadianceHook::irradiance): then that lobe is neither light-sampled
    // nor continued, and the path goes on by its specular lobe alone. Not at the depth limit,
    // where the lobe gathers no indirect light either way.
    vec3 probe(0.0f);
    const bool probe_lit = (kMirror || kDielectric) && !last && hook_ != nullptr &&
                           diffuse > 0.0f && specular > 0.0f &&
                           hook_->irradiance(v.instance, sp.shading_normal, probe);

    vec3 origin(0.0f);
    if (diffuse > 0.0f) {
      origin = w_.starts.origin(v.start);
      const vec3 f = m.base_color * (diffuse * kInvPi);
      if constexpr (kPunctual) {
        // Whitted's own shadow rays (shading.h), so that with nothing else the images agree.
        // Sampled for the whole wave where there are few lights (w_.starts: sample_light and
        // shadow_tfar), here otherwise; the same values either way.
        const auto emit = [&](const vec3& direction, float tfar, const vec3& value) {
          add_shadow(origin, direction, tfar, p, p.throughput * value);
        };
        if (batched_lights()) {
          const VertexStarts& ls = w_.starts;
          for (std::size_t l = 0, e = v.start; l < tables_.lights.size(); ++l, e += ls.count())
            lit_shadow_ray(
                ls.light_direction(e), ls.irradiance(e), [&] { return ls.ptfar[e]; }, sp, f, emit);
        } else {
          for (const gpu::GpuLight& light : tables_.lights)
            punctual_shadow_ray(light, sp, origin, f, emit);
        }
      }
      if (probe_lit) contribute(p.slot, p.leaving, p.throughput * m.base_color * (diffuse * probe));
      // Area lights are sampled towards the next vertex, which the last one does not have (the
      // BSDF strategy would need a ray beyond the depth limit).
      if constexpr (kArea) {
        if (!last && !probe_lit && settings_.sampling != LightSampling::Bsdf) {
          // The light sample (sample_area_light), drawn for the whole wave.
          const VertexStarts& ls = w_.starts;
          const std::size_t k = v.start;
          const float pdf = ls.pdf[k];
          const vec3 to_light = ls.to_light(k);
          const vec3 light = ls.emission(k);
          const float cos_theta = glm::dot(to_light, sp.shading_normal);
          if (pdf > 0.0f && glm::dot(to_light, sp.geometric_normal) > 0.0f && cos_theta > 0.0f &&
              max_component(light) > 0.0f) {
            const float weight = settings_.sampling == LightSampling::Mis
                                     ? power_heuristic(pdf, p_diffuse * cos_theta * kInvPi)
                                     : 1.0f;
            // Stop short of the light point, relatively: its own triangle must not block it.
            add_shadow(origin, to_light, ls.distance[k] * (1.0f - 1e-4f), p,
                       p.throughput * f * light * (cos_theta * weight / pdf));
          }
        }
      }
    }
    if (last || !(total > 0.0f)) return;

    // The continuation: a lobe picked by its weight, the throughput divided by its probability.
    // Dimensions: 0 the lobe, 1 reflect or refract, 2 and 3 the diffuse direction.
    // The next path and its ray are assembled in registers and written to their waves part by
    // part (a Path copied whole after piecewise writes was read back before they had reached
    // memory, as punctual_shadow_ray notes of rays).
    vec3 throughput = p.throughput;
    float bsdf_pdf = 0.0f;
    vec3 ray_origin = origin, direction;
    RayKind kind = RayKind::Reflection;
    bool exits = false; // a specular ray leaving the object outwards
    if (!(kMirror || kDielectric) || (!probe_lit && u.bsdf[0] * total < diffuse)) {
      direction = cosine_direction(sp.shading_normal, u.bsdf[2], u.bsdf[3]);
      const float cos_theta = glm::dot(direction, sp.shading_normal);
      if (glm::dot(direction, sp.geometric_normal) <= 0.0f || !(cos_theta > 0.0f)) return;
      // f·cos / pdf = (diffuse·base/π·cos) / (p_diffuse·cos/π).
      throughput *= m.base_color * total;
      bsdf_pdf = p_diffuse * cos_theta * kInvPi;
    } else {
      // The specular lobe, picked with probability specular / total (or 1 when the probe lit
      // the diffuse one).
      throughput *= probe_lit ? specular : total;
      bool reflect = true;
      if constexpr (kDielectric) {
        const SpecularSplit split = split_specular(m, sp, d);
        const float both = split.reflect_weight + split.refract_weight;
        reflect = u.bsdf[1] * both < split.reflect_weight;
        direction = reflect ? split.reflect_direction : split.refract_direction;
      } else {
        vec3 r = reflect_direction(d, sp.shading_normal);
        if (glm::dot(r, sp.geometric_normal) <= 0.0f) r = reflect_direction(d, sp.geometric_normal);
        direction = glm::normalize(r);
      }
      kind = reflect ? RayKind::Reflection : RayKind::Refraction;
      exits = reflect == sp.front_face;
      ray_origin = offset_ray_origin(sp.spawn_point, sp.spawn_error,
                                     reflect ? sp.geometric_normal : -sp.geometric_normal);
    }
    if (depth >= kRouletteDepth) {
      const float survival = std::clamp(max_component(throughput), 0.05f, 1.0f);
      if (u.roulette >= survival) return;
      throughput /= survival;
    }
    if (!(max_component(throughput) > 0.0f)) return; // a black surface ends it
    ++counts_[kind];
    if (hook_ != nullptr && exits)
      w_.exits.push_back(PathExit{std::uint32_t(w_.paths.size()), v.instance, kind,
                                  throughput / glm::max(p.throughput, vec3(1e-30f))});
    Path& next = w_.paths.emplace_back();
    next.throughput = throughput;
    next.bsdf_pdf = bsdf_pdf;
    next.previous = sp.position;
    next.slot = p.slot;
    next.pixel = p.pixel;
    next.stream = p.stream;
    next.sample = p.sample;
    next.leaving = p.leaving;
    store_ray(w_.rays.emplace_back(), ray_origin, direction,
              std::numeric_limits<float>::infinity());
  }

  /// A shadow ray (stored part by part: see punctual_shadow_ray) and what it brings unblocked.
  void add_shadow(const vec3& origin, const vec3& direction, float tfar, const Path& p,
                  const vec3& value) {
    store_ray(w_.shadow_rays.emplace_back(), origin, direction, tfar);
    w_.shadow_slot.push_back(p.slot);
    w_.shadow_chain.push_back(p.leaving);
    w_.shadow_value.push_back(value);
    if (settings_.shadows) count_ray(p.leaving);
  }

  /// The slot of a path traced for the cache alone (CacheAnswer::Refresh): its sample already
  /// holds the cached value, so what it gathers goes to its leaving record only.
  static constexpr std::uint32_t kDetached = 0xffffffffu;

  /// Adds to a sample's radiance (unless the path is detached from it), and to every leaving
  /// record open on its path.
  void contribute(std::uint32_t slot, std::uint32_t chain, const vec3& value) {
    if (slot != kDetached) w_.radiance[slot] += value;
    for (; chain != kNoInstance; chain = w_.records[chain].parent) w_.records[chain].sum += value;
  }

  void count_ray(std::uint32_t chain) {
    for (; chain != kNoInstance; chain = w_.records[chain].parent) ++w_.records[chain].ray.rays;
  }

  /// The first hit of a record's ray, and what every open record of the path saw.
  void note_hit(std::uint32_t chain, const Hit& hit) {
    if (chain == kNoInstance) return;
    LeavingRadiance& inner = w_.records[chain].ray;
    const std::uint32_t entity =
        hit.hit() ? tables_.instances[hit.instance].entity_index : kNoInstance;
    if (std::isnan(inner.hit_t)) {
      inner.hit_t = hit.hit() ? hit.t : std::numeric_limits<float>::infinity();
      inner.hit_entity = entity;
    }
    if (entity == kNoInstance) return;
    const std::uint32_t bit = entity_bit(entity);
    for (; chain != kNoInstance; chain = w_.records[chain].parent)
      w_.records[chain].ray.seen |= bit;
  }

  /// Opens a leaving record for each of the wave's rays that leave a cached object (before they
  /// are traced: the record counts the ray and everything after it).
  void open_leaving(std::uint32_t depth) {
    w_.exit_of.assign(w_.wave_paths.size(), kNoInstance);
    for (std::size_t q = 0; q < w_.wave_exits.size(); ++q) {
      const PathExit& e = w_.wave_exits[q];
      Path& p = w_.wave_paths[e.path];
      const Ray& r = w_.wave_rays[e.path];
      PathLeaving rec;
      LeavingRadiance& l = rec.ray;
      l.from = tables_.entity(e.instance);
      l.instance = e.instance;
      l.kind = e.kind;
      l.exits = true;
      l.answer = CacheAnswer::Trace;
      l.depth = depth;
      l.pixel = p.pixel;
      l.sample = p.sample;
      l.origin = r.origin;
      l.direction = r.direction;
      l.weight = e.weight;
      l.throughput = p.throughput;
      l.radiance = vec3(0.0f);
      l.cached = vec3(0.0f);
      l.hit_t = std::numeric_limits<float>::quiet_NaN();
      l.hit_entity = kNoInstance;
      l.seen = 0;
      l.rays = 0;
      rec.sum = vec3(0.0f);
      rec.emitted = vec3(0.0f);
      rec.parent = p.leaving;
      w_.exit_of[e.path] = std::uint32_t(q);
      p.leaving = std::uint32_t(w_.records.size());
      w_.records.push_back(rec);
    }
  }

  /// Once the wave is traced: the leaving rays that hit something are offered to the hook
  /// (when it wants lookups) with their first hit, which it may accept for its cached value
  /// (the radiance scattered there towards the ray; docs/design/ray-cache.md, "Path mode").
  void look_up_leaving(std::uint32_t depth) {
    if (!frame_.lookups || w_.wave_exits.empty()) return;
    w_.queries.clear();
    w_.query_path.clear();
    for (std::size_t k = 0; k < w_.wave_paths.size(); ++k) {
      if (w_.exit_of[k] == kNoInstance || !w_.hits[k].hit()) continue;
      const Path& p = w_.wave_paths[k];
      const LeavingRadiance& l = w_.records[p.leaving].ray;
      LeavingQuery q{l.instance, p.pixel, depth, l.origin, l.direction, p.sample};
      q.hit_entity = l.hit_entity;
      q.hit_t = l.hit_t;
      w_.queries.push_back(q);
      w_.query_path.push_back(std::uint32_t(k));
    }
    w_.answers.assign(w_.queries.size(), CachedRadiance{});
    hook_->lookup(w_.queries, w_.answers);
    for (std::size_t q = 0; q < w_.queries.size(); ++q) {
      const CachedRadiance& a = w_.answers[q];
      LeavingRadiance& l = w_.records[w_.wave_paths[w_.query_path[q]].leaving].ray;
      // Path mode's answers: Use or Refresh; anything else traces on.
      if (a.answer != CacheAnswer::Use && a.answer != CacheAnswer::Refresh) continue;
      l.answer = a.answer;
      l.cached = a.radiance;
      l.seen |= a.seen; // what the cached value saw
    }
  }

  /// The batch's leaving records to the hook, in the order they were opened (deterministic): a
  /// traced ray's radiance is what its path gathered after its first hit (the emission there
  /// left out: the traced ray gives it exactly), over its throughput.
  void deliver_leaving() {
    if (w_.records.empty()) return;
    w_.delivered.clear();
    for (PathLeaving& rec : w_.records) {
      LeavingRadiance& l = rec.ray;
      if (l.answer == CacheAnswer::Use) {
        l.radiance = l.cached;
      } else {
        const vec3 scattered = rec.sum - rec.emitted;
        for (int c = 0; c < 3; ++c) {
          l.radiance[c] = l.throughput[c] > 0.0f ? scattered[c] / l.throughput[c] : 0.0f;
          l.emitted[c] = l.throughput[c] > 0.0f ? rec.emitted[c] / l.throughput[c] : 0.0f;
        }
        if (!std::isfinite(l.radiance.x + l.radiance.y + l.radiance.z + l.emitted.x + l.emitted.y +
                           l.emitted.z))
          continue;
      }
      w_.delivered.push_back(l);
    }
    hook_->leaving(w_.delivered);
  }

  /// The wave's shadow rays in one batch; each unblocked one adds its value to its sample, in
  /// the order they were emitted. `coherent`: wave 0's, from the tile's primary hits towards the
  /// same lights, which a backend may trace in packets (Tracer::occluded_coherent: the same
  /// answers as occluded()).
  void trace_shadows(bool coherent) {
    if (w_.shadow_rays.empty()) return;
    w_.blocked.resize(w_.shadow_rays.size());
    if (settings_.shadows) {
      counts_[RayKind::Shadow] += w_.shadow_rays.size();
      if (coherent)
        frame_.tracer.occluded_coherent(w_.shadow_rays, w_.blocked);
      else
        frame_.tracer.occluded(w_.shadow_rays, w_.blocked);
    } else {
      std::fill(w_.blocked.begin(), w_.blocked.end(), std::uint8_t{0});
    }
    for (std::size_t k = 0; k < w_.shadow_rays.size(); ++k)
      if (w_.blocked[k] == 0) contribute(w_.shadow_slot[k], w_.shadow_chain[k], w_.shadow_value[k]);
    w_.shadow_rays.clear();
    w_.shadow_slot.clear();
    w_.shadow_chain.clear();
    w_.shadow_value.clear();
  }

  const FrameInputs& frame_;
  const SceneTables& tables_;
  const TraceSettings& settings_;
  PathWave& w_;
  const PrimaryHits& primary_;
  RayCounts& counts_;
  const EmitterTable& emitters_;
  RadianceHook* hook_;
};

template <bool kArea, bool kPunctual, bool kMirror, bool kDielectric>
void run_path_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
                   RayCounts& counts) {
  PathTile<kArea, kPunctual, kMirror, kDielectric>(frame, scratch, counts).run(tile);
}

using PathTileFn = void (*)(const FrameInputs&, const PacketTile&, TileScratch&, RayCounts&);

/// The instantiation for a scene's features, indexed by area | punctual << 1 | mirror << 2 |
/// dielectric << 3.
template <std::size_t... I>
constexpr std::array<PathTileFn, sizeof...(I)> path_tile_table(std::index_sequence<I...>) {
  return {&run_path_tile<(I & 1) != 0, (I & 2) != 0, (I & 4) != 0, (I & 8) != 0>...};
}
constexpr auto kPathTiles = path_tile_table(std::make_index_sequence<16>{});

} // namespace

void path_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
               RayCounts& counts) {
  const EmitterTable empty;
  FrameInputs inputs = frame;
  if (inputs.emitters == nullptr) inputs.emitters = &empty;
  const SceneFeatures& f = inputs.emitters->features();
  const bool punctual = f.punctual_lights || !frame.tables.lights.empty();
  kPathTiles[std::size_t(f.area_lights) | std::size_t(punctual) << 1 | std::size_t(f.mirrors) << 2 |
             std::size_t(f.dielectrics) << 3](inputs, tile, scratch, counts);
}

} // namespace specula::detail
