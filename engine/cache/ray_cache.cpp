#include "specula/cache/ray_cache.h"

#include "specula/cache/cube_map.h"
#include "specula/core/error.h"
#include "specula/scene/components/material.h"
#include "specula/scene/components/ray_cache_cube.h"
#include "specula/shared/cache_layout.h"
#include "specula/trace/lights.h"

#include <glm/gtc/packing.hpp>
#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <numbers>

namespace specula::cache {

// ---------------------------------------------------------------------------------------------
// Settings names

std::optional<LookupMode> parse_lookup_mode(std::string_view name) {
  if (name == "direction") return LookupMode::Direction;
  if (name == "tau") return LookupMode::Tau;
  if (name == "march") return LookupMode::March;
  return std::nullopt;
}

const char* lookup_mode_name(LookupMode mode) {
  switch (mode) {
  case LookupMode::Direction: return "direction";
  case LookupMode::Tau: return "tau";
  case LookupMode::March: return "march";
  }
  return "unknown";
}

std::optional<CachePolicy> parse_cache_policy(std::string_view name) {
  if (name == "off") return CachePolicy::Off;
  if (name == "on") return CachePolicy::On;
  if (name == "auto") return CachePolicy::Auto;
  return std::nullopt;
}

const char* cache_policy_name(CachePolicy policy) {
  switch (policy) {
  case CachePolicy::Off: return "off";
  case CachePolicy::On: return "on";
  case CachePolicy::Auto: return "auto";
  }
  return "unknown";
}

// ---------------------------------------------------------------------------------------------
// Texels

Texel make_texel(const vec3& radiance, float distance, std::uint32_t hit_entity,
                 std::uint32_t seen, std::uint32_t rays) {
  Texel t;
  // Half floats overflow at 65504: larger radiance (or distance) saturates rather than turning
  // into infinity; a miss keeps +inf.
  const vec3 c = glm::clamp(radiance, vec3(0.0f), vec3(65504.0f));
  t.rgb[0] = glm::packHalf1x16(c.x);
  t.rgb[1] = glm::packHalf1x16(c.y);
  t.rgb[2] = glm::packHalf1x16(c.z);
  t.distance = std::isfinite(distance) ? glm::packHalf1x16(std::min(distance, 65504.0f))
                                       : std::uint16_t(0x7c00);
  t.hit = hit_entity;
  t.seen = fold_seen(seen);
  t.rays = std::uint8_t(std::min(rays, 255u));
  t.state = kValid;
  return t;
}

vec3 texel_radiance(const Texel& t) {
  return vec3(glm::unpackHalf1x16(t.rgb[0]), glm::unpackHalf1x16(t.rgb[1]),
              glm::unpackHalf1x16(t.rgb[2]));
}

float texel_distance(const Texel& t) { return glm::unpackHalf1x16(t.distance); }

// ---------------------------------------------------------------------------------------------
// Irradiance from the incoming-light probe (Ramamoorthi & Hanrahan 2001: the real spherical
// harmonics to order 2, the cosine lobe's coefficients π, 2π/3, π/4 folded in)

namespace {

void sh_basis(const vec3& n, float (&y)[9]) {
  y[0] = 0.282095f;
  y[1] = 0.488603f * n.y;
  y[2] = 0.488603f * n.z;
  y[3] = 0.488603f * n.x;
  y[4] = 1.092548f * n.x * n.y;
  y[5] = 1.092548f * n.y * n.z;
  y[6] = 0.315392f * (3.0f * n.z * n.z - 1.0f);
  y[7] = 1.092548f * n.x * n.z;
  y[8] = 0.546274f * (n.x * n.x - n.y * n.y);
}

} // namespace

vec3 IrradianceSH::evaluate(const vec3& n) const {
  float y[9];
  sh_basis(n, y);
  vec3 e(0.0f);
  for (int i = 0; i < 9; ++i) e += c[i] * y[i];
  return glm::max(e, vec3(0.0f));
}

IrradianceSH project_irradiance(std::span<const IncomingCell> cells, std::uint32_t side,
                                float& coverage) {
  // Each cell weighs its solid angle, (2/side)² / (1 + s² + t²)^{3/2} at its centre (s, t on the
  // face in [-1, 1]); the unsampled ones take the mean radiance of the sampled.
  double sh[9][3] = {};
  double missing[9] = {};
  double sampled = 0.0, total = 0.0;
  vec3 mean_sum(0.0f);
  const float texel = 2.0f / float(side);
  for (std::uint32_t face = 0; face < kFaceCount; ++face)
    for (std::uint32_t y = 0; y < side; ++y)
      for (std::uint32_t x = 0; x < side; ++x) {
        const IncomingCell& cell = cells[(face * side + y) * side + x];
        const float u = (float(x) + 0.5f) / float(side), v = (float(y) + 0.5f) / float(side);
        const float s = 2.0f * u - 1.0f, t = 2.0f * v - 1.0f;
        const float d = 1.0f + s * s + t * t;
        const double omega = double(texel * texel / (d * std::sqrt(d)));
        float b[9];
        sh_basis(glm::normalize(cube_direction(face, u, v)), b);
        total += omega;
        if (cell.weight > 0.0f) {
          const vec3 L = vec3(cell.sum[0], cell.sum[1], cell.sum[2]) / cell.weight;
          for (int i = 0; i < 9; ++i)
            for (int ch = 0; ch < 3; ++ch) sh[i][ch] += double(L[ch]) * b[i] * omega;
          mean_sum += L * float(omega);
          sampled += omega;
        } else {
          for (int i = 0; i < 9; ++i) missing[i] += b[i] * omega;
        }
      }
  coverage = total > 0.0 ? float(sampled / total) : 0.0f;
  const vec3 mean = sampled > 0.0 ? mean_sum / float(sampled) : vec3(0.0f);
  constexpr double kPi = std::numbers::pi;
  const double band[9] = {kPi,     2 * kPi / 3, 2 * kPi / 3, 2 * kPi / 3, kPi / 4,
                          kPi / 4, kPi / 4,     kPi / 4,     kPi / 4};
  IrradianceSH out;
  for (int i = 0; i < 9; ++i)
    for (int ch = 0; ch < 3; ++ch)
      out.c[i][ch] = float((sh[i][ch] + double(mean[ch]) * missing[i]) * band[i] / kPi);
  return out;
}

// ---------------------------------------------------------------------------------------------
// Cubes

namespace {

/// What a lookup costs against tracing one ray, for the auto policy's count-based accounting
/// (measured by `specula_bench --section cache-costs` on the mirror-spheres scene; see
/// docs/design/ray-cache.md). Counts, not clocks, decide, so decisions and images are the same
/// from run to run.
constexpr double kLookupRayCost = 0.05;    // one texel fetch and its acceptance test
constexpr double kMarchStepRayCost = 0.02; // one step of the distance march
constexpr std::uint32_t kMaxMarchSteps = gpu::kCubeMarchSteps; // the device marches alike
constexpr std::uint32_t kRefineSteps = gpu::kCubeRefineSteps;
constexpr std::uint64_t kMinErrorSamples = 64;
/// Fixed point of the incoming-light samples (2^20 a unit of radiance; a sample is clamped to
/// [0, 10^6], so a frame's sums stay far inside 64 bits).
constexpr double kIncomingScale = 1048576.0;
constexpr float kIncomingMax = 1e6f;
/// The auto policy's error estimate: each frame's verified errors weigh this much of the next
/// frame's (about the last two frames count).
constexpr double kErrorDecay = 0.5;
/// Auto: a cube that left a rung for its error tries it again after this many frames in slower
/// rungs or off (the error of a direction cache depends on where the camera has been: it can be
/// within the bound again once the camera rests).
constexpr std::uint32_t kRetryFrames = 32;
constexpr std::uint32_t kEvaluationVerifyEvery = 4;

std::uint32_t mix_hash(std::uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdULL;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ULL;
  x ^= x >> 33;
  return std::uint32_t(x);
}

/// Fill ahead's tiles (RayCacheStore::fill_ahead): `side`² a face, each `size`² texels. Both are
/// powers of two, so a tile is addressed as the texel of a cube of resolution `side`
/// (texel_of, texel_index).
struct TileGrid {
  std::uint32_t side, size;
  explicit TileGrid(std::uint32_t resolution)
      : side(std::min(resolution, RayCacheStore::kFillAheadTiles)),
        size(std::max(1u, resolution / side)) {}
  [[nodiscard]] std::uint32_t count() const { return kFaceCount * side * side; }
};

/// The ladder auto walks down when the error bound is not kept: fastest first.
struct Rung {
  LookupMode mode;
  float tau_deg;
};
constexpr Rung kLadder[] = {{LookupMode::Direction, 0.0f},
                            {LookupMode::March, 0.5f},
                            {LookupMode::Tau, 1.0f},
                            {LookupMode::Tau, 0.25f}};
constexpr int kLadderSize = int(std::size(kLadder));

std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

/// A bounding sphere of an instance: its mesh's bounds centre, and the farthest vertex from it,
/// scaled by the transform's largest axis scale (tighter than the world box's half-diagonal: a
/// sphere mesh gets its own radius, not √3 times it).
Sphere instance_sphere(const SceneTables& tables, std::uint32_t slot) {
  const gpu::GpuInstance& inst = tables.instances[slot];
  const gpu::GpuMesh& mesh = tables.meshes[inst.mesh];
  const vec3 centre = 0.5f * (mesh.bounds_min + mesh.bounds_max);
  float r2 = 0.0f;
  const vec3* p = tables.positions.data() + mesh.first_vertex;
  for (std::uint32_t i = 0; i < mesh.vertex_count; ++i) {
    const vec3 d = p[i] - centre;
    r2 = std::max(r2, glm::dot(d, d));
  }
  const mat3 m(inst.world_from_object);
  const float scale = std::max({glm::length(m[0]), glm::length(m[1]), glm::length(m[2])});
  // Rounded up a little: the sphere must hold every vertex after the transform's rounding.
  return Sphere{vec3(inst.world_from_object * vec4(centre, 1.0f)),
                std::sqrt(r2) * scale * (1.0f + 1e-5f)};
}

/// Whether the segment from p (length `length` along unit d; +inf: a ray) passes through s.
bool segment_meets_sphere(const vec3& p, const vec3& d, float length, const Sphere& s) {
  const vec3 m = s.centre - p;
  const float along = glm::clamp(glm::dot(m, d), 0.0f, length);
  const vec3 closest = p + d * along;
  return glm::dot(closest - s.centre, closest - s.centre) <= s.radius * s.radius;
}

/// Texel generations (CubeView::generation). Only changed on the thread that applies writes and
/// invalidations, but cubes of several stores may live at once.
std::atomic<std::uint64_t> texel_generations{0};
std::uint64_t next_generation() { return ++texel_generations; }

} // namespace

struct RayCacheStore::Cube {
  ecs::Entity owner;
  std::uint32_t instance = 0;
  std::uint32_t resolution = 64;
  vec3 centre{0.0f};
  float radius = 0.0f; ///< the owner's bounding sphere: where leaving rays start
  std::vector<Texel> texels;
  std::vector<ProbeTexel> probe; ///< path mode (sized on its first sample)
  /// Path mode: the incoming-light probe (sized on its first sample), its irradiance and whether
  /// it lights the diffuse lobe yet.
  std::vector<IncomingCell> incoming;
  IrradianceSH irradiance;
  bool irradiance_ready = false;
  [[nodiscard]] std::uint32_t incoming_side() const { return std::min(resolution, kIncomingCells); }
  /// The frame's samples for `incoming`, per cell: red, green, blue in fixed point
  /// (kIncomingScale) and the count — integer sums, the same in whatever order the tiles
  /// deliver them.
  std::vector<std::int64_t> incoming_batch;
  /// The frame's traced leaving samples that hit within kNearRadii radii, and all of them; the
  /// latest frame's share of near ones.
  std::uint64_t near_samples = 0, incoming_samples = 0;
  float near_share = 0.0f;
  void clear_incoming() {
    std::fill(incoming.begin(), incoming.end(), IncomingCell{});
    irradiance_ready = false;
  }
  /// Fill ahead: a bit per tile (TileGrid) that lookups addressed since the last fill_ahead,
  /// set from the lookup threads through atomic_ref.
  std::vector<std::uint32_t> addressed;
  std::uint64_t generation = next_generation();
  /// The texels changed since generation `journal_from` (a device copy made at that generation
  /// sends only those: CubeView::changes); past an eighth of the texels it gives up
  /// (journal_whole) and a copy goes up whole. Restarted by restart_journals.
  std::vector<std::uint32_t> journal;
  std::uint64_t journal_from = generation;
  bool journal_whole = false;
  std::vector<std::uint32_t> edges; ///< by entity index: valid texels whose first hit it is
  std::uint64_t valid = 0;
  // Policy.
  int rung = 0;
  LookupMode mode = LookupMode::Direction;
  float tau_deg = 0.5f;
  float cos_tau = 1.0f;
  bool enabled = true;
  bool evaluating = true; ///< auto: verify often until the error of this mode is known
  std::string reason;
  /// Σ |throughput·(cached − traced)|² over verified rays, and their number, since the mode was
  /// chosen, each frame's weighing kErrorDecay of the one after it.
  double err_sum = 0.0;
  double err_samples = 0.0;
  double estimated_psnr = 0.0;
  std::uint32_t frames_in_mode = 0;
  /// Auto's retry: the fastest rung left for its error (-1: none), the frames spent since in
  /// slower rungs or off, and where a retry that fails goes back to (-1: off).
  int retry_rung = -1;
  std::uint32_t frames_below_retry = 0;
  bool retrying = false;
  int return_rung = -1;
  double saved_ms = 0.0;
  /// Rays fill ahead traced for this cube since the last decide: a cost its savings must cover.
  std::uint64_t fill_rays = 0;
  // This frame, from lookups (several threads).
  std::atomic<std::uint64_t> lookups{0}, outdated{0}, rejected{0}, march_steps{0};
  std::atomic<std::uint64_t> offered_rays{0}; ///< what the served texels cost when traced
  // This frame, from leaving rays (under the store's mutex).
  std::uint64_t used = 0, used_rays = 0, traced = 0, traced_rays = 0, verified = 0;

  void set_rung(int r) {
    rung = r;
    mode = kLadder[r].mode;
    tau_deg = kLadder[r].tau_deg;
    cos_tau = std::cos(glm::radians(tau_deg));
    err_sum = 0.0;
    err_samples = 0.0;
    evaluating = true;
    frames_in_mode = 0;
  }
  void set_mode(LookupMode m, float tau) {
    mode = m;
    tau_deg = tau;
    cos_tau = std::cos(glm::radians(tau));
  }
  /// Whether texel i holds anything an invalidation must consider: a valid value, or path
  /// samples still being averaged.
  [[nodiscard]] bool holds(std::uint32_t i) const {
    return texels[i].valid() || (!probe.empty() && probe[i].samples > 0);
  }
  /// Texel i changed: a new generation, and i in the journal.
  void changed(std::uint32_t i) {
    generation = next_generation();
    if (journal_whole) return;
    if (journal.size() >= texels.size() / 8) {
      journal_whole = true;
      journal.clear();
      journal.shrink_to_fit();
      return;
    }
    journal.push_back(i);
  }
  void outdate(std::uint32_t i) {
    Texel& t = texels[i];
    if (!probe.empty() && probe[i].samples > 0) {
      probe[i] = ProbeTexel{};
      changed(i);
    }
    if (!t.valid()) return;
    t.state &= std::uint8_t(~kValid);
    --valid;
    changed(i);
    if (t.hit < edges.size()) --edges[t.hit];
  }
  void store(std::uint32_t i, const Texel& value) {
    outdate(i);
    texels[i] = value;
    ++valid;
    changed(i);
    if (value.hit != kNoInstance) {
      if (value.hit >= edges.size()) edges.resize(value.hit + 1, 0);
      ++edges[value.hit];
    }
  }
  /// Path mode: one frame's batch for texel i — n samples summing to `sum` (n may be 0) and
  /// the lookups its direction had (`asked`). The batch joins the moving average (ProbeTexel); the
  /// first samples after an outdate set the texel's hit, distance and cost (`first`); the texel
  /// serves while the average's weight is at least `serve_at`.
  void accumulate(std::uint32_t i, const vec3& sum, std::uint32_t n, std::uint32_t asked,
                  const Texel& first, std::uint16_t seen, std::uint32_t serve_at) {
    if (probe.empty()) probe.assign(texels.size(), ProbeTexel{});
    ProbeTexel& p = probe[i];
    if (asked > 0) p.lookups = asked;
    if (n == 0) return;
    Texel& t = texels[i];
    if (p.samples == 0) {
      outdate(i);
      t = first;
      t.state = kOutdated;
      t.seen = 0;
    }
    for (int c = 0; c < 3; ++c) p.sum[c] = p.sum[c] * (1.0f - kProbeDecay) + sum[c];
    p.weight = p.weight * (1.0f - kProbeDecay) + float(n);
    p.samples = n > 0xffffffffu - p.samples ? 0xffffffffu : p.samples + n;
    const Texel m =
        make_texel(vec3(p.sum[0], p.sum[1], p.sum[2]) / p.weight, 0.0f, kNoInstance, 0, 0);
    std::copy(std::begin(m.rgb), std::end(m.rgb), std::begin(t.rgb));
    t.seen |= seen;
    changed(i);
    const bool serves = p.weight >= float(serve_at);
    if (serves == t.valid()) return;
    if (serves) {
      t.state |= kValid;
      ++valid;
      if (t.hit != kNoInstance) {
        if (t.hit >= edges.size()) edges.resize(t.hit + 1, 0);
        ++edges[t.hit];
      }
    } else {
      // Its weight fell below the bound (fewer refreshing samples than the bound needs): it
      // keeps its samples but stops serving until it has enough again.
      t.state &= std::uint8_t(~kValid);
      --valid;
      if (t.hit < edges.size()) --edges[t.hit];
    }
  }
  std::uint64_t flush() {
    const std::uint64_t was = valid;
    clear_incoming();
    if (!probe.empty()) std::fill(probe.begin(), probe.end(), ProbeTexel{});
    for (Texel& t : texels) t.state &= std::uint8_t(~kValid);
    std::fill(edges.begin(), edges.end(), 0u);
    valid = 0;
    if (was > 0) {
      generation = next_generation();
      journal_whole = true;
      journal.clear();
    }
    return was;
  }
};

struct RayCacheStore::Candidate {
  std::uint32_t cube;
  std::uint32_t texel;
  std::uint32_t pixel;
  std::uint32_t order; ///< depth, kind
  std::uint64_t tie;   ///< direction bits: a total order among a pixel's rays
  Texel value;
  vec3 radiance; ///< path mode: the sample, at full precision
  std::uint32_t group = 0; ///< path mode: its texel's entry in apply_writes' sums
  bool sample = true;      ///< path mode: false for a served lookup (it only counts)
};

RayCacheStore::RayCacheStore(CacheSettings settings) : settings_(settings) {
  if (settings_.verify_every == 0) settings_.verify_every = 1;
}

RayCacheStore::~RayCacheStore() = default;

std::size_t RayCacheStore::cube_count() const { return cubes_.size(); }

std::uint32_t RayCacheStore::verify_period(const Cube& c) const {
  return c.evaluating ? kEvaluationVerifyEvery : settings_.verify_every;
}

CubeView RayCacheStore::cube(std::size_t i) const {
  const Cube& c = *cubes_.at(i);
  return CubeView{c.owner,
                  c.instance,
                  c.resolution,
                  c.centre,
                  c.texels,
                  c.probe,
                  c.mode,
                  c.enabled,
                  c.cos_tau,
                  c.generation,
                  c.journal_whole ? 0u : c.journal_from,
                  c.journal,
                  settings_.policy == CachePolicy::Auto ? verify_period(c) : 0u,
                  c.incoming,
                  c.incoming_side(),
                  c.irradiance_ready && c.enabled};
}

std::optional<std::size_t> RayCacheStore::cube_of(ecs::Entity owner) const {
  for (std::size_t i = 0; i < cubes_.size(); ++i)
    if (cubes_[i]->owner == owner) return i;
  return std::nullopt;
}

std::vector<std::pair<std::uint32_t, std::uint32_t>> RayCacheStore::edges(std::size_t i) const {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
  const Cube& c = *cubes_.at(i);
  for (std::uint32_t e = 0; e < c.edges.size(); ++e)
    if (c.edges[e] > 0) out.emplace_back(e, c.edges[e]);
  return out;
}

std::uint64_t RayCacheStore::flush() {
  std::uint64_t n = 0;
  for (auto& c : cubes_) n += c->flush();
  return n;
}

// ---------------------------------------------------------------------------------------------
// Invalidation

InvalidationStats RayCacheStore::invalidate(ecs::Registry& registry, const SceneLayer& layer) {
  const SceneTables& tables = layer.tables();
  const SceneDelta& delta = layer.delta();
  InvalidationStats stats;
  for (const auto& c : cubes_) stats.flush_all += c->valid;

  // 1. The set of cubes: entities with a RayCacheCube, a reflective or refractive material and
  // an instance in the layer.
  std::vector<std::unique_ptr<Cube>> kept;
  std::vector<ecs::Entity> owners;
  registry.view<RayCacheCube>().each([&](ecs::Entity e, RayCacheCube& request) {
    const Material* m = registry.try_get<Material>(e);
    if (m == nullptr || !(m->is_reflective() || m->is_refractive())) return;
    const std::optional<std::uint32_t> slot = layer.instance_of(e);
    if (!slot) return;
    const std::uint32_t resolution =
        settings_.resolution != 0 ? settings_.resolution : request.resolution;
    std::unique_ptr<Cube> cube;
    for (auto& c : cubes_)
      if (c && c->owner == e && c->resolution == resolution) cube = std::move(c);
    if (!cube) {
      cube = std::make_unique<Cube>();
      cube->owner = e;
      cube->resolution = resolution;
      cube->texels.assign(std::size_t(kFaceCount) * resolution * resolution, Texel{});
      cube->addressed.assign((TileGrid(resolution).count() + 31) / 32, 0u);
      if (settings_.policy == CachePolicy::Auto) {
        start_auto(*cube);
      } else {
        cube->set_mode(settings_.lookup, settings_.tau_deg);
        cube->evaluating = false;
        cube->reason = std::string("--cache on: ") + lookup_mode_name(cube->mode) + " mode";
      }
      cube->instance = *slot;
      const Sphere own = instance_sphere(tables, *slot);
      cube->centre = own.centre;
      cube->radius = own.radius;
    }
    cube->instance = *slot;
    kept.push_back(std::move(cube));
  });
  // A fixed order (by owner), whatever order the view walks in.
  std::sort(kept.begin(), kept.end(), [](const auto& a, const auto& b) {
    return a->owner.index < b->owner.index;
  });
  cubes_ = std::move(kept);
  cube_of_instance_.assign(tables.instances.size(), -1);
  for (std::size_t i = 0; i < cubes_.size(); ++i) cube_of_instance_[cubes_[i]->instance] = int(i);

  // 2. What changed, as entities with their old and new bounds.
  auto grow = [&](std::uint32_t index) {
    if (index >= bounds_.size()) {
      bounds_.resize(index + 1);
      has_bounds_.resize(index + 1, 0);
    }
  };
  struct Change {
    std::uint32_t entity;
    std::optional<Sphere> before, after;
  };
  std::vector<Change> changes;
  auto changed = [&](std::uint32_t slot, bool removed) {
    if (!removed && !tables.live(slot)) return;
    const gpu::GpuInstance& inst = tables.instances[slot];
    const std::uint32_t e = inst.entity_index;
    grow(e);
    Change ch{e, std::nullopt, std::nullopt};
    if (has_bounds_[e] != 0) ch.before = bounds_[e];
    if (!removed) {
      ch.after = instance_sphere(tables, slot);
      bounds_[e] = *ch.after;
      has_bounds_[e] = 1;
    } else {
      has_bounds_[e] = 0;
    }
    changes.push_back(ch);
  };
  // The delta describes one sync. A store that missed a sync that changed something (caching
  // switched off while objects moved, a store made for a layer that synced before) cannot tell
  // what changed in between: every texel goes. Missed syncs that changed nothing (another
  // renderer's frames of a still scene) cost nothing. The same sync seen twice brings nothing
  // new.
  const bool fresh = layer.syncs() != synced_;
  const bool missed = fresh && layer.missed_changes(synced_);
  synced_ = layer.syncs();
  bool flush_everything = missed || (fresh && delta.static_rebuilt);
  bool flush_surfaces = fresh && (delta.lights_changed || delta.materials_changed);
  if (fresh && !missed) {
    for (const std::uint32_t s : delta.instances_removed) {
      // The slot is freed: its entity index is still in the table entry.
      if (s < tables.instances.size()) changed(s, true);
    }
    for (const std::uint32_t s : delta.instances_added) changed(s, false);
    for (const std::uint32_t s : delta.instances_moved) changed(s, false);
    for (const std::uint32_t s : delta.instances_deformed) changed(s, false);
  }
  if (flush_everything)
    for (std::uint32_t s = 0; s < tables.instances.size(); ++s)
      if (tables.live(s)) {
        const std::uint32_t e = tables.instances[s].entity_index;
        grow(e);
        bounds_[e] = instance_sphere(tables, s);
        has_bounds_[e] = 1;
      }

  // 3. Apply to every cube.
  std::vector<std::uint64_t> generations;
  for (const auto& cp : cubes_) generations.push_back(cp->generation);
  for (auto& cp : cubes_) {
    Cube& c = *cp;
    const Sphere own = instance_sphere(tables, c.instance);
    const bool owner_moved = glm::any(glm::notEqual(own.centre, c.centre)) ||
                             std::any_of(changes.begin(), changes.end(), [&](const Change& ch) {
                               return ch.entity == c.owner.index;
                             });
    if (flush_everything || owner_moved) {
      stats.outdated += c.flush();
      c.centre = own.centre;
      c.radius = own.radius;
      continue;
    }
    if (changes.empty() && !flush_surfaces) continue;
    const std::uint32_t res = c.resolution;
    const float texel_angle = texel_half_angle(res);
    struct Test {
      std::uint32_t entity;
      std::uint16_t bit;
      bool cone = false; // the new bounds, seen from the centre
      vec3 axis{0.0f};
      float cos_cone = 1.0f;
      std::vector<Sphere> shadows; // old and new bounds, as occluders of the stored hit points
    };
    std::vector<Test> tests;
    for (const Change& ch : changes) {
      Test t;
      t.entity = ch.entity;
      t.bit = seen_bit16(ch.entity);
      if (ch.after) {
        // Leaving rays start anywhere on the owner, within c.radius of the centre, and a texel
        // serves all of them: it must go if a ray from any of those points in its direction
        // could meet the new bounds — the cone of half-angle asin((r + R) / distance).
        const vec3 to = ch.after->centre - c.centre;
        const float dist = glm::length(to);
        const float reach = ch.after->radius + c.radius;
        if (dist <= reach) {
          t.cone = true; // the centre is inside its bounds: it can be anywhere
          t.cos_cone = -2.0f;
          t.axis = vec3(0, 0, 1);
        } else {
          t.cone = true;
          t.axis = to / dist;
          t.cos_cone = std::cos(std::min(std::numbers::pi_v<float>,
                                         std::asin(std::min(1.0f, reach / dist)) +
                                             texel_angle));
        }
        t.shadows.push_back(*ch.after);
      }
      if (ch.before) t.shadows.push_back(*ch.before);
      tests.push_back(std::move(t));
    }
    const std::vector<gpu::GpuLight>& lights = tables.lights;
    tbb::combinable<std::vector<std::uint32_t>> hits_found;
    tbb::parallel_for(
        tbb::blocked_range<std::uint32_t>(0, std::uint32_t(c.texels.size()), 4096),
        [&](const tbb::blocked_range<std::uint32_t>& range) {
          std::vector<std::uint32_t>& out = hits_found.local();
          for (std::uint32_t i = range.begin(); i != range.end(); ++i) {
            const Texel& tx = c.texels[i];
            if (!c.holds(i)) continue;
            const float d = texel_distance(tx);
            const bool finite = std::isfinite(d);
            if (flush_surfaces && finite) {
              out.push_back(i);
              continue;
            }
            bool stale = false;
            vec3 dir(0.0f);
            bool have_dir = false;
            for (const Test& t : tests) {
              if (tx.hit == t.entity || (tx.seen & t.bit) != 0) {
                stale = true;
                break;
              }
              if (!have_dir) {
                dir = texel_direction(i, res);
                have_dir = true;
              }
              // It may now see the entity, closer than what it saw.
              if (t.cone && glm::dot(dir, t.axis) >= t.cos_cone) {
                stale = true;
                break;
              }
              // Its hit point may now be (or no longer be) in the entity's shadow.
              // The stored point is where the ray from the centre would be: the rays the texel
              // served hit within the owner's radius (and a texel's width) of it, so the
              // occluder grows by that much.
              if (finite && !t.shadows.empty()) {
                const vec3 p = c.centre + dir * d;
                const float widen = c.radius + d * 2.0f * texel_angle;
                for (const gpu::GpuLight& light : lights) {
                  const LightSample ls = sample_light(light, p);
                  for (const Sphere& s : t.shadows)
                    if (segment_meets_sphere(p, ls.to_light, ls.distance,
                                             Sphere{s.centre, s.radius + widen}))
                      stale = true;
                }
                if (stale) break;
              }
            }
            if (stale) out.push_back(i);
          }
        });
    hits_found.combine_each([&](const std::vector<std::uint32_t>& v) {
      for (const std::uint32_t i : v) {
        c.outdate(i);
        ++stats.outdated;
      }
    });
  }
  // Path mode's incoming-light probe sums what arrives from every direction: whatever outdated a
  // texel of the cube may have changed it, and it starts again.
  for (std::size_t i = 0; i < cubes_.size(); ++i)
    if (cubes_[i]->generation != generations[i]) cubes_[i]->clear_incoming();
  last_invalidation_ = stats;
  return stats;
}

// ---------------------------------------------------------------------------------------------
// Prefill

namespace {

/// The point of the sphere (centre c, radius r) that reflects direction s towards the eye: its
/// normal bisects s and the direction to the eye (a few fixed-point steps, from the direction to
/// the eye seen from the centre). The centre when the eye is inside or s points back at the eye.
vec3 reflection_point(const vec3& c, float r, const vec3& s, const vec3& eye) {
  const vec3 to_eye = eye - c;
  if (glm::dot(to_eye, to_eye) <= r * r) return c;
  vec3 v = glm::normalize(to_eye);
  vec3 p = c;
  for (int k = 0; k < 4; ++k) {
    const vec3 h = s + v;
    const float len = glm::length(h);
    if (!(len > 1e-4f)) return c;
    p = c + (r / len) * h;
    v = glm::normalize(eye - p);
  }
  return p;
}

} // namespace

std::uint64_t RayCacheStore::trace_texels(Cube& c, std::span<const std::uint32_t> todo,
                                          const Tracer& tracer, const SceneLayer& layer,
                                          const TraceSettings& trace,
                                          const std::optional<vec3>& eye, bool ahead) {
  // In chunks: the rays and their samples stay a few MiB whatever the cube's size (4096² faces
  // hold 100 million texels).
  constexpr std::size_t kChunk = std::size_t(1) << 16;
  std::vector<Ray> rays;
  std::vector<RadianceSample> out;
  for (std::size_t first = 0; first < todo.size(); first += kChunk) {
    const std::span<const std::uint32_t> part =
        todo.subspan(first, std::min(kChunk, todo.size() - first));
    rays.resize(part.size());
    out.resize(part.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, part.size(), 1024),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        for (std::size_t k = range.begin(); k < range.end(); ++k) {
                          const vec3 s = texel_direction(part[k], c.resolution);
                          rays[k] =
                              Ray{eye ? reflection_point(c.centre, c.radius, s, *eye) : c.centre,
                                  0.0f, s, std::numeric_limits<float>::infinity()};
                        }
                      });
    const RayCounts traced = trace_radiance(tracer, layer, trace, rays, 1, c.instance, out);
    if (ahead) c.fill_rays += traced.total(); // prefill is the ideal bound: not charged
    for (std::size_t k = 0; k < part.size(); ++k) {
      // Texels keep the distance from the centre to what the ray hit (the tau and march tests).
      const float distance =
          std::isinf(out[k].t)
              ? out[k].t
              : glm::length(rays[k].origin + rays[k].direction * out[k].t - c.centre);
      Texel t = make_texel(out[k].radiance, distance, out[k].entity, out[k].seen, out[k].rays);
      t.state |= kTexelPrefilled;
      c.store(part[k], t);
    }
  }
  pending_prefilled_ += todo.size();
  return todo.size();
}

std::uint64_t RayCacheStore::prefill(const Tracer& tracer, const SceneLayer& layer,
                                     const TraceSettings& trace) {
  std::uint64_t filled = 0;
  // Prefill traces Whitted radiance from the centre; path mode's probes fill from path samples.
  if (trace.mode == TraceMode::Path) return 0;
  constexpr std::size_t kBatch = std::size_t(1) << 16;
  std::vector<std::uint32_t> todo;
  for (auto& cp : cubes_) {
    Cube& c = *cp;
    if (!c.enabled) continue;
    for (std::uint32_t i = 0; i < c.texels.size(); ++i) {
      if (!c.texels[i].valid()) todo.push_back(i);
      if (todo.size() == kBatch || (i + 1 == c.texels.size() && !todo.empty())) {
        filled += trace_texels(c, todo, tracer, layer, trace, std::nullopt, false);
        todo.clear();
      }
    }
  }
  return filled;
}

std::uint64_t RayCacheStore::fill_ahead(const Tracer& tracer, const SceneLayer& layer,
                                        const TraceSettings& trace,
                                        const std::optional<vec3>& eye) {
  const std::uint32_t budget = settings_.fill_ahead;
  const bool on = budget != 0 && trace.mode != TraceMode::Path && !averaging_;
  // Each cube's walk over its tiles: the tiles reached so far and the latest ring.
  struct Walk {
    TileGrid grid{1};
    std::vector<std::uint8_t> reached;
    std::vector<std::uint32_t> frontier;
    std::vector<std::uint32_t> todo; ///< texels picked
  };
  std::vector<Walk> walks(cubes_.size());
  for (std::size_t ci = 0; ci < cubes_.size(); ++ci) {
    Cube& c = *cubes_[ci];
    Walk& w = walks[ci];
    w.grid = TileGrid(c.resolution);
    if (on && c.enabled)
      for (std::uint32_t t = 0; t < w.grid.count(); ++t)
        if ((c.addressed[t >> 5] >> (t & 31u)) & 1u) w.frontier.push_back(t);
    std::fill(c.addressed.begin(), c.addressed.end(), 0u);
    w.reached.assign(w.frontier.empty() ? 0 : w.grid.count(), 0);
    for (const std::uint32_t t : w.frontier) w.reached[t] = 1;
  }
  // Ring by ring over every cube, nearest first; within a ring, tile by tile in an order spread
  // by a hash, until the budget is spent.
  std::uint64_t picked = 0;
  struct Ranked {
    std::uint32_t hash, cube, tile;
  };
  std::vector<Ranked> ring_tiles;
  for (std::uint32_t ring = 0; ring <= kFillAheadRings && picked < budget; ++ring) {
    ring_tiles.clear();
    for (std::uint32_t ci = 0; ci < walks.size(); ++ci)
      for (const std::uint32_t t : walks[ci].frontier)
        ring_tiles.push_back(
            Ranked{mix_hash((std::uint64_t(ci) << 32 | t) ^ (frame_ << 40)), ci, t});
    if (ring_tiles.empty()) break;
    std::sort(ring_tiles.begin(), ring_tiles.end(), [](const Ranked& a, const Ranked& b) {
      return a.hash != b.hash ? a.hash < b.hash
                              : (a.cube != b.cube ? a.cube < b.cube : a.tile < b.tile);
    });
    for (const Ranked& r : ring_tiles) {
      const Cube& c = *cubes_[r.cube];
      Walk& w = walks[r.cube];
      const std::uint32_t face = r.tile / (w.grid.side * w.grid.side);
      const std::uint32_t ty = (r.tile / w.grid.side) % w.grid.side, tx = r.tile % w.grid.side;
      const std::uint32_t base = face * c.resolution * c.resolution;
      for (std::uint32_t y = ty * w.grid.size; y < (ty + 1) * w.grid.size && picked < budget; ++y)
        for (std::uint32_t x = tx * w.grid.size; x < (tx + 1) * w.grid.size && picked < budget;
             ++x) {
          const std::uint32_t i = base + y * c.resolution + x;
          if (c.texels[i].valid()) continue;
          w.todo.push_back(i);
          ++picked;
        }
      if (picked >= budget) break;
    }
    if (picked >= budget || ring == kFillAheadRings) break;
    // The next ring: the 8 neighbours of each tile, across face edges (the neighbour's centre
    // on the face's plane, addressed as a direction).
    for (Walk& w : walks) {
      std::vector<std::uint32_t> next;
      const float inv = 1.0f / float(w.grid.side);
      for (const std::uint32_t t : w.frontier) {
        const std::uint32_t face = t / (w.grid.side * w.grid.side);
        const int ty = int((t / w.grid.side) % w.grid.side), tx = int(t % w.grid.side);
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            if (dx == 0 && dy == 0) continue;
            const std::uint32_t nt =
                texel_index(cube_coord(cube_direction(face, (float(tx + dx) + 0.5f) * inv,
                                                      (float(ty + dy) + 0.5f) * inv)),
                            w.grid.side);
            if (w.reached[nt]) continue;
            w.reached[nt] = 1;
            next.push_back(nt);
          }
      }
      w.frontier = std::move(next);
    }
  }
  std::uint64_t filled = 0;
  for (std::size_t ci = 0; ci < walks.size(); ++ci)
    filled += trace_texels(*cubes_[ci], walks[ci].todo, tracer, layer, trace, eye, true);
  return filled;
}

// ---------------------------------------------------------------------------------------------
// The hook

void RayCacheStore::begin_frame(std::uint32_t width, std::uint32_t height, TraceMode mode) {
  width_ = std::max(1u, width);
  height_ = std::max(1u, height);
  const bool averaging = mode == TraceMode::Path;
  if (averaging != averaging_) {
    // Whitted's texels hold exact radiance without indirect light, path mode's the mean of
    // samples that include it: one must not serve the other.
    averaging_ = averaging;
    for (auto& c : cubes_) {
      c->flush();
      c->probe.clear();
      c->probe.shrink_to_fit();
      if (settings_.policy == CachePolicy::Auto) start_auto(*c);
    }
  }
  ++frame_;
  lookup_log_.clear();
  lookups_ = false;
  for (auto& c : cubes_) {
    c->lookups = 0;
    c->outdated = 0;
    c->rejected = 0;
    c->march_steps = 0;
    c->offered_rays = 0;
    c->used = c->used_rays = c->traced = c->traced_rays = c->verified = 0;
    lookups_ = lookups_ || c->enabled;
  }
  candidates_.clear();
}

bool RayCacheStore::serving() const {
  // Auto never lets path mode's texels serve: measured not to pay (docs/design/ray-cache.md).
  return settings_.path_serve && settings_.policy != CachePolicy::Auto;
}

void RayCacheStore::restart_journals() {
  for (auto& c : cubes_) {
    c->journal.clear();
    c->journal_whole = false;
    c->journal_from = c->generation;
  }
}

bool RayCacheStore::needs_every_lookup() const {
  return log_lookups_ || (settings_.fill_ahead != 0 && !averaging_);
}

CubeFrameCounts RayCacheStore::frame_counts(std::size_t i) const {
  const Cube& c = *cubes_.at(i);
  CubeFrameCounts n;
  n.lookups = c.lookups.load();
  n.outdated = c.outdated.load();
  n.rejected = c.rejected.load();
  n.march_steps = c.march_steps.load();
  n.offered_rays = c.offered_rays.load();
  n.used = c.used;
  n.used_rays = c.used_rays;
  n.traced = c.traced;
  n.traced_rays = c.traced_rays;
  return n;
}

void RayCacheStore::add_frame_counts(std::size_t i, const CubeFrameCounts& n) {
  const std::lock_guard lock(mutex_);
  Cube& c = *cubes_.at(i);
  c.lookups += n.lookups;
  c.outdated += n.outdated;
  c.rejected += n.rejected;
  c.march_steps += n.march_steps;
  c.offered_rays += n.offered_rays;
  c.used += n.used;
  c.used_rays += n.used_rays;
  c.traced += n.traced;
  c.traced_rays += n.traced_rays;
}

bool RayCacheStore::wants_lookups() const {
  // Path mode asks only where texels may serve.
  return lookups_ && (!averaging_ || serving());
}

bool RayCacheStore::wants_leaving() const {
  // Path mode's leaving samples feed the texels' probes, or the incoming-light probes.
  return lookups_ && (!averaging_ || serving() || settings_.path_irradiance);
}

namespace {

struct Answer {
  CacheAnswer answer = CacheAnswer::Trace;
  std::uint32_t texel = 0;
  bool rejected = false;
  bool outdated = false;
  std::uint32_t steps = 0;
};

/// Direction from the shading point p to the cached hit `centre + s·distance` within τ of d.
bool within_tau(const vec3& centre, const vec3& s, float distance, const vec3& p, const vec3& d,
                float cos_tau) {
  const vec3 v = centre + s * distance - p;
  const float len = glm::length(v);
  return len > 0.0f && glm::dot(v, d) >= cos_tau * len;
}

} // namespace

// The march: find where the ray p + t·d first goes beyond the stored surface, |q − c| = D(q − c),
// stepping about one texel of angle (or the remaining gap to the surface, as |q − c| grows at
// most as fast as t) at a time, then bisecting; accept the texel found if its stored hit lies
// within τ of the ray. A ray whose direction from the centre converges on d without crossing
// anything sees what the texel of d saw: a miss, confirmed by an occlusion ray.
static Answer march(const std::vector<Texel>& texels, std::uint32_t res, const vec3& centre,
                    const vec3& p, const vec3& d, float cos_tau) {
  Answer a;
  const vec3 pc = p - centre;
  const float texel_angle = 2.0f / float(res);
  const float scale = std::max(glm::length(pc), 1e-6f);
  float t = 0.0f;
  float t_inside = 0.0f;
  for (std::uint32_t step = 0; step < kMaxMarchSteps; ++step) {
    ++a.steps;
    const vec3 q = pc + t * d;
    const float r = glm::length(q);
    const std::uint32_t ti = texel_of(r > 0.0f ? q : d, res);
    const Texel& tx = texels[ti];
    if (!tx.valid()) {
      a.outdated = true;
      return a;
    }
    const float D = texel_distance(tx);
    if (std::isinf(D)) {
      // Nothing stored this way. Once q's direction is within a texel of d, it never leaves it.
      if (r > 0.0f && glm::dot(q, d) >= r * march_cos_half_texel(res)) {
        const std::uint32_t td = texel_of(d, res);
        if (!texels[td].valid()) {
          a.outdated = true;
          return a;
        }
        if (!std::isinf(texel_distance(texels[td]))) {
          a.rejected = true;
          return a;
        }
        a.answer = CacheAnswer::UseIfClear;
        a.texel = td;
        return a;
      }
    } else if (r >= D) {
      // Crossed between t_inside and t: bisect.
      float lo = t_inside, hi = t;
      std::uint32_t found = ti;
      for (std::uint32_t k = 0; k < kRefineSteps; ++k) {
        ++a.steps;
        const float mid = 0.5f * (lo + hi);
        const vec3 qm = pc + mid * d;
        const float rm = glm::length(qm);
        const std::uint32_t tm = texel_of(rm > 0.0f ? qm : d, res);
        if (!texels[tm].valid()) {
          a.outdated = true;
          return a;
        }
        const float Dm = texel_distance(texels[tm]);
        if (!std::isinf(Dm) && rm >= Dm) {
          hi = mid;
          found = tm;
        } else {
          lo = mid;
        }
      }
      // The stored surface where the ray crossed it: on the ray when the surface is continuous
      // there, off it at a silhouette (the stored distance jumped), which the τ test rejects.
      const vec3 q_hit = pc + hi * d;
      const float r_hit = glm::length(q_hit);
      const vec3 s = r_hit > 0.0f ? q_hit / r_hit : d;
      if (within_tau(centre, s, texel_distance(texels[found]), p, d, cos_tau)) {
        a.answer = CacheAnswer::Use;
        a.texel = found;
      } else {
        a.rejected = true;
      }
      return a;
    }
    t_inside = t;
    // Step: about one texel of angle as seen from the centre, and never past the surface when
    // the stored distance does not change (|q − c| grows at most as fast as t).
    const float perp = r > 0.0f ? glm::length(glm::cross(d, q)) / r : 0.0f;
    float dt = perp > 1e-12f ? texel_angle * r * r / perp : std::numeric_limits<float>::infinity();
    if (!std::isinf(D)) dt = std::min(dt, std::max(D - r, 0.0f) + 1e-4f * scale);
    t += std::max(dt, 1e-4f * scale);
    if (!std::isfinite(t)) break;
  }
  a.rejected = true; // ran out of steps: trace
  return a;
}

void RayCacheStore::lookup(std::span<const LeavingQuery> queries,
                           std::span<CachedRadiance> answers) const {
  // Counters gathered per batch (a batch mostly addresses one cube), added once.
  struct Local {
    std::uint64_t lookups = 0, outdated = 0, rejected = 0, steps = 0, offered_rays = 0;
  };
  thread_local std::vector<Local> local;
  local.assign(cubes_.size(), Local{});
  // Whitted frames under auto trace one accepted lookup in verify_every to measure the error
  // (path mode refreshes its probes instead).
  const bool verify = settings_.policy == CachePolicy::Auto;
  thread_local std::vector<LookupRecord> log;
  log.clear();
  for (std::size_t k = 0; k < queries.size(); ++k) {
    const LeavingQuery& q = queries[k];
    CachedRadiance& out = answers[k];
    out = CachedRadiance{};
    const auto note = [&](LookupOutcome outcome) {
      if (log_lookups_) log.push_back(LookupRecord{q.pixel, q.depth, q.instance, outcome});
    };
    const std::int32_t ci =
        q.instance < cube_of_instance_.size() ? cube_of_instance_[q.instance] : -1;
    if (ci < 0) continue;
    const Cube& c = *cubes_[std::size_t(ci)];
    if (!c.enabled) continue;
    Local& l = local[std::size_t(ci)];
    ++l.lookups;
    if (settings_.fill_ahead != 0 && !averaging_) {
      // Fill ahead starts from the tiles the lookups addressed (a set: the same whatever the
      // threads' order).
      const std::uint32_t tile = texel_of(q.direction, TileGrid(c.resolution).side);
      std::atomic_ref<std::uint32_t> word(cubes_[std::size_t(ci)]->addressed[tile >> 5]);
      const std::uint32_t bit = 1u << (tile & 31u);
      if ((word.load(std::memory_order_relaxed) & bit) == 0)
        word.fetch_or(bit, std::memory_order_relaxed);
    }
    if (averaging_) {
      // Path mode asks once the leaving ray is traced: the texel of its direction serves if
      // its probe belongs to the surface the ray hit (which stands in for the parallax tests),
      // with the radiance scattered there towards the ray.
      const std::uint32_t ti = texel_of(q.direction, c.resolution);
      const Texel& tx = c.texels[ti];
      if (!tx.valid()) {
        ++l.outdated;
        note(LookupOutcome::Outdated);
        continue;
      }
      if (tx.hit != q.hit_entity) {
        ++l.rejected;
        note(LookupOutcome::Rejected);
        continue;
      }
      note(LookupOutcome::Accepted);
      out.answer = CacheAnswer::Use;
      out.radiance = texel_radiance(tx);
      out.seen = tx.seen | entity_bit(tx.hit);
      // The probe stays fresh: about path_refresh of the lookups its direction had last frame
      // are traced on anyway, for the probe alone (the sample takes the mean either way).
      // Chosen by a hash of the sample, so frames do not depend on the thread count.
      const std::uint32_t asked = std::max(1u, c.probe[ti].lookups);
      const std::uint64_t key = (std::uint64_t(q.pixel) << 8) ^ (std::uint64_t(q.depth) << 2) ^
                                (frame_ << 40) ^ (std::uint64_t(q.sample) << 24) ^
                                std::uint64_t(ci);
      if (std::uint64_t(mix_hash(key)) * asked < std::uint64_t(settings_.path_refresh) << 32)
        out.answer = CacheAnswer::Refresh;
      else
        l.offered_rays += tx.rays;
      continue;
    }
    Answer a;
    if (c.mode == LookupMode::March) {
      a = march(c.texels, c.resolution, c.centre, q.origin, q.direction, c.cos_tau);
      l.steps += a.steps;
    } else {
      a.texel = texel_of(q.direction, c.resolution);
      const Texel& tx = c.texels[a.texel];
      if (!tx.valid()) {
        a.outdated = true;
      } else if (c.mode == LookupMode::Direction) {
        a.answer = CacheAnswer::Use;
      } else {
        const float D = texel_distance(tx);
        if (std::isinf(D))
          a.answer = CacheAnswer::UseIfClear; // a miss: confirm nothing is in the way
        else if (within_tau(c.centre, q.direction, D, q.origin, q.direction, c.cos_tau))
          a.answer = CacheAnswer::Use;
        else
          a.rejected = true;
      }
    }
    if (a.outdated) ++l.outdated;
    if (a.rejected) ++l.rejected;
    if (a.answer == CacheAnswer::Trace) {
      note(a.outdated ? LookupOutcome::Outdated : LookupOutcome::Rejected);
      continue;
    }
    note(LookupOutcome::Accepted);
    const Texel& tx = c.texels[a.texel];
    out.answer = a.answer;
    out.radiance = texel_radiance(tx);
    out.clear_distance = std::numeric_limits<float>::infinity();
    out.seen = tx.seen | (tx.hit != kNoInstance ? entity_bit(tx.hit) : 0u);
    const std::uint64_t cost = tx.rays;
    if (verify) {
      if (verify_chosen(q.pixel, q.depth, q.sample, std::uint32_t(frame_), std::uint32_t(ci),
                        verify_period(c)))
        out.answer = CacheAnswer::Verify;
    }
    if (out.answer == CacheAnswer::Use || out.answer == CacheAnswer::UseIfClear)
      l.offered_rays += cost;
  }
  if (!log.empty()) {
    const std::lock_guard lock(log_mutex_);
    lookup_log_.insert(lookup_log_.end(), log.begin(), log.end());
  }
  for (std::size_t i = 0; i < local.size(); ++i) {
    if (local[i].lookups == 0) continue;
    Cube& c = *cubes_[i];
    c.lookups.fetch_add(local[i].lookups, std::memory_order_relaxed);
    c.outdated.fetch_add(local[i].outdated, std::memory_order_relaxed);
    c.rejected.fetch_add(local[i].rejected, std::memory_order_relaxed);
    c.march_steps.fetch_add(local[i].steps, std::memory_order_relaxed);
    c.offered_rays.fetch_add(local[i].offered_rays, std::memory_order_relaxed);
  }
}

bool RayCacheStore::irradiance(std::uint32_t instance, const vec3& n, vec3& out) const {
  if (!averaging_ || !settings_.path_irradiance || instance >= cube_of_instance_.size())
    return false;
  const std::int32_t ci = cube_of_instance_[instance];
  if (ci < 0) return false;
  const Cube& c = *cubes_[std::size_t(ci)];
  if (!c.enabled || !c.irradiance_ready) return false;
  out = c.irradiance.evaluate(n);
  return true;
}

void RayCacheStore::leaving(std::span<const LeavingRadiance> rays) {
  const std::lock_guard lock(mutex_);
  for (const LeavingRadiance& r : rays) {
    if (!r.exits || r.instance >= cube_of_instance_.size()) continue;
    const std::int32_t ci = cube_of_instance_[r.instance];
    if (ci < 0) continue;
    Cube& c = *cubes_[std::size_t(ci)];
    if (!c.enabled) continue; // off: nothing it holds is read, so nothing is written
    bool sample = true;
    switch (r.answer) {
    case CacheAnswer::Use:
    case CacheAnswer::UseIfClear:
      ++c.used;
      c.used_rays += r.rays;
      if (!averaging_) continue;
      sample = false; // path mode counts the lookup (the probe's refresh rate)
      break;
    case CacheAnswer::Refresh:
      ++c.used;
      ++c.traced;
      c.traced_rays += r.rays;
      break;
    case CacheAnswer::Verify: {
      ++c.verified;
      ++c.traced;
      c.traced_rays += r.rays;
      const vec3 e = r.throughput * (r.cached - r.radiance);
      c.err_sum += double(glm::dot(e, e));
      c.err_samples += 1.0;
      continue;
    }
    case CacheAnswer::Trace:
      ++c.traced;
      c.traced_rays += r.rays;
      break;
    }
    if (averaging_ && sample && settings_.path_irradiance) {
      // The incoming-light probe takes every traced sample, whatever it hit: all the light
      // that arrived along it.
      const std::uint32_t side = c.incoming_side();
      if (c.incoming_batch.empty())
        c.incoming_batch.assign(std::size_t(kFaceCount) * side * side * 4, 0);
      std::int64_t* cell = &c.incoming_batch[std::size_t(texel_of(r.direction, side)) * 4];
      const vec3 light = r.radiance + r.emitted;
      for (int ch = 0; ch < 3; ++ch)
        cell[ch] +=
            std::llround(double(std::clamp(light[ch], 0.0f, kIncomingMax)) * kIncomingScale);
      ++cell[3];
      ++c.incoming_samples;
      if (r.hit_t < kNearRadii * c.radius) ++c.near_samples;
    }
    if (averaging_ && !serving()) continue; // no texel serves: nothing to write
    const std::uint32_t ti = texel_of(r.direction, c.resolution);
    // Only outdated texels are written (the paper); path mode's average every sample.
    if (!averaging_ && c.texels[ti].valid()) continue;
    const float distance =
        std::isinf(r.hit_t) ? r.hit_t : glm::length(r.origin + r.direction * r.hit_t - c.centre);
    Candidate cand;
    cand.cube = std::uint32_t(ci);
    cand.texel = ti;
    cand.pixel = r.pixel;
    cand.order = (r.sample << 12) | (r.depth << 4) | std::uint32_t(r.kind);
    std::uint32_t bx, by;
    std::memcpy(&bx, &r.direction.x, 4);
    std::memcpy(&by, &r.direction.y, 4);
    cand.tie = (std::uint64_t(bx) << 32) | by;
    cand.sample = sample;
    if (sample) {
      cand.value = make_texel(r.radiance, distance, r.hit_entity, r.seen, r.rays);
      cand.radiance = r.radiance;
    }
    candidates_.push_back(cand);
  }
}

std::uint64_t RayCacheStore::apply_writes() {
  // The first candidate of each texel in a fixed order (path mode: all of them, summed in that
  // order): the result does not depend on which thread traced which tile. Sorted as compact keys
  // (cube and texel, pixel and order, direction bits; unique) rather than as candidates.
  struct Key {
    std::uint64_t texel, pixel, tie;
    std::uint32_t index;
  };
  std::vector<Key> keys(candidates_.size());
  for (std::size_t i = 0; i < candidates_.size(); ++i) {
    const Candidate& c = candidates_[i];
    keys[i] = Key{(std::uint64_t(c.cube) << 32) | c.texel, (std::uint64_t(c.pixel) << 32) | c.order,
                  c.tie, std::uint32_t(i)};
  }
  tbb::parallel_sort(keys.begin(), keys.end(), [](const Key& a, const Key& b) {
    if (a.texel != b.texel) return a.texel < b.texel;
    if (a.pixel != b.pixel) return a.pixel < b.pixel;
    return a.tie < b.tie;
  });
  // Path mode: each texel's samples summed in that order, and its lookups counted; a texel's
  // probe belongs to one surface (the entity its first sample hit), so samples that hit another
  // are left out; its first sample stands for the group (hit, distance, cost).
  struct Sum {
    vec3 radiance{0.0f};
    std::uint32_t n = 0, lookups = 0;
    std::uint16_t seen = 0;
    std::uint32_t surface = kNoInstance - 1; ///< unset
  };
  std::vector<Candidate> unique;
  std::vector<Sum> sums;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const Candidate& c = candidates_[keys[k].index];
    if (k == 0 || keys[k].texel != keys[k - 1].texel) {
      unique.push_back(c);
      sums.push_back(Sum{});
      if (averaging_) {
        const Cube& cube = *cubes_[c.cube];
        if (!cube.probe.empty() && cube.probe[c.texel].samples > 0)
          sums.back().surface = cube.texels[c.texel].hit;
      }
    }
    if (averaging_) {
      Sum& s = sums.back();
      ++s.lookups;
      if (!c.sample) continue;
      if (s.surface == kNoInstance - 1) s.surface = c.value.hit;
      if (c.value.hit != s.surface) continue;
      if (s.n == 0) unique.back() = c;
      s.radiance += c.radiance;
      ++s.n;
      s.seen |= c.value.seen | (c.value.hit != kNoInstance ? seen_bit16(c.value.hit) : 0);
    }
  }
  for (std::size_t k = 0; k < unique.size(); ++k) unique[k].group = std::uint32_t(k);
  if (settings_.fill_budget != 0 && unique.size() > settings_.fill_budget) {
    // Spread the budget over the cubes' faces rather than filling from one corner.
    std::stable_sort(unique.begin(), unique.end(), [&](const Candidate& a, const Candidate& b) {
      return mix_hash(((std::uint64_t(a.cube) << 32) | a.texel) ^ frame_) <
             mix_hash(((std::uint64_t(b.cube) << 32) | b.texel) ^ frame_);
    });
    unique.resize(settings_.fill_budget);
  }
  std::uint64_t written = 0;
  for (const Candidate& c : unique) {
    if (averaging_) {
      const Sum& s = sums[c.group];
      cubes_[c.cube]->accumulate(c.texel, s.radiance, s.n, s.lookups, c.value, s.seen,
                                 std::max(1u, settings_.path_samples));
      written += s.n > 0 ? 1 : 0;
    } else {
      cubes_[c.cube]->store(c.texel, c.value);
      ++written;
    }
  }
  return written;
}

void RayCacheStore::report(CacheCounts& out) const { out = counts_; }

void RayCacheStore::start_auto(Cube& c) const {
  c.retry_rung = -1;
  c.frames_below_retry = 0;
  c.retrying = false;
  c.return_rung = -1;
  if (averaging_) {
    // Measured (docs/cache-report/path-cache.md): texels that serve leaving rays reached
    // uncached path tracing's error later on every scene and setting there, so auto never lets
    // them serve; the incoming-light probe lighting the object's diffuse lobe reached it sooner
    // on both scenes, so auto keeps it where the object's surroundings are far (decide).
    c.enabled = settings_.path_irradiance;
    c.reason = c.enabled ? "path mode: the incoming-light probe lights the diffuse lobe "
                           "(measured to reach uncached path tracing's error sooner); texels "
                           "do not serve (measured not to pay)"
                         : "path mode: off (texels that serve were measured to reach uncached "
                           "path tracing's error later; --cache-irradiance is off)";
    return;
  }
  int start = 0;
  for (int r = 0; r < kLadderSize; ++r)
    if (kLadder[r].mode == settings_.lookup) {
      start = r;
      break;
    }
  c.enabled = true;
  c.set_rung(start);
  c.reason = std::string("starting in ") + lookup_mode_name(c.mode) + " mode";
}

void RayCacheStore::decide(Cube& c, double ns_per_ray, double frame_rays) {
  const std::uint64_t lookups = c.lookups.load();
  // What the cube saved, in rays: the subtrees it did not trace (what they cost when they were
  // traced into the texels), less the confirming rays, what the lookups cost and the rays fill
  // ahead traced for it before the frame.
  const double saved_rays = double(c.offered_rays.load()) - double(c.used_rays) -
                            double(lookups) * kLookupRayCost -
                            double(c.march_steps.load()) * kMarchStepRayCost - double(c.fill_rays);
  c.fill_rays = 0;
  c.saved_ms = saved_rays * ns_per_ray * 1e-6;
  if (settings_.policy == CachePolicy::Auto && averaging_ && c.enabled &&
      c.near_share > kNearShare) {
    // The probe stands for the object's every point only where what it sees is far: here it
    // would not, and keeping the records would only cost.
    c.enabled = false;
    c.reason = format("path mode: %.0f%% of its leaving rays hit something within %.0f radii: "
                      "the incoming-light probe assumes far surroundings; off",
                      100.0 * c.near_share, double(kNearRadii));
    return;
  }
  if (settings_.policy != CachePolicy::Auto || averaging_) return;
  if (c.retry_rung >= 0 && !c.retrying && (!c.enabled || c.rung > c.retry_rung) &&
      ++c.frames_below_retry >= kRetryFrames) {
    const std::string was = c.enabled ? lookup_mode_name(c.mode) : "off";
    c.return_rung = c.enabled ? c.rung : -1;
    c.retrying = true;
    c.frames_below_retry = 0;
    c.enabled = true;
    c.set_rung(c.retry_rung);
    c.reason = format("%.0f frames in ", double(kRetryFrames)) + was + " mode since " +
               lookup_mode_name(c.mode) + " mode missed the error bound: trying it again";
    return;
  }
  if (!c.enabled) return;
  ++c.frames_in_mode;

  // Error: the verified rays' squared error, scaled to every accepted ray of the frame, over
  // the image's 3·N values; the bound is shared by the enabled cubes.
  const double pixels = double(width_) * double(height_);
  const std::uint64_t accepted = c.used + c.verified;
  if (c.err_samples > 0) {
    const double mse = c.err_sum / c.err_samples * double(accepted) / (3.0 * pixels);
    c.estimated_psnr = mse > 0.0 ? -10.0 * std::log10(mse) : 200.0;
  }
  std::size_t enabled = 0;
  for (const auto& other : cubes_) enabled += other->enabled ? 1 : 0;
  const double bound = settings_.max_error_db + 10.0 * std::log10(double(std::max<std::size_t>(1, enabled)));
  // The estimate is of the texels as they are now: what was verified frames ago (before later
  // writes, while the camera was elsewhere) fades, by kErrorDecay a frame.
  const double verified = c.err_samples;
  c.err_sum *= kErrorDecay;
  c.err_samples *= kErrorDecay;
  if (verified >= double(kMinErrorSamples)) {
    if (c.estimated_psnr < bound) {
      const std::string was = lookup_mode_name(c.mode);
      const double psnr = c.estimated_psnr;
      if (c.retrying) {
        // Still not within the bound: straight back to where the retry started.
        c.retrying = false;
        c.frames_below_retry = 0;
        if (c.return_rung >= 0) {
          c.set_rung(c.return_rung);
        } else {
          c.enabled = false;
        }
        c.reason = format("estimated %.1f dB, below the %.1f dB bound again: ", psnr, bound) +
                   was + " → " + (c.enabled ? lookup_mode_name(c.mode) : "off");
        return;
      }
      if (c.retry_rung < 0 || c.rung < c.retry_rung) c.retry_rung = c.rung;
      c.frames_below_retry = 0;
      if (c.rung + 1 < kLadderSize) {
        c.set_rung(c.rung + 1);
        c.reason = format("estimated %.1f dB, below the %.1f dB bound: ", psnr, bound) + was +
                   " → " + lookup_mode_name(c.mode) +
                   (c.mode == LookupMode::Direction ? "" : format(" (tau %.2f deg)", c.tau_deg));
      } else {
        c.enabled = false;
        c.reason = format("estimated %.1f dB, below the %.1f dB bound in every lookup mode: off",
                          psnr, bound);
      }
      return;
    }
    if (c.evaluating) {
      c.evaluating = false;
      c.retrying = false;
      c.reason = format("estimated %.1f dB, within the %.1f dB bound: ", c.estimated_psnr, bound) +
                 lookup_mode_name(c.mode) + " mode kept";
    }
  }
  // Speed: once the cube is filled (few lookups find outdated texels) and the mode has run two
  // frames — or after four frames in any case: a mode that is still filling then (a march that
  // keeps meeting outdated texels) will not pay soon — it must save more than it costs, 1% of
  // the frame's rays, or the cube tries the next mode down the ladder, and at its end goes off:
  // a scene that gains nothing runs at uncached speed.
  const bool filled = lookups > 0 && double(c.outdated.load()) < 0.05 * double(lookups);
  if ((filled && c.frames_in_mode >= 2 && !c.evaluating) || c.frames_in_mode >= 4) {
    if (saved_rays < 0.01 * frame_rays) {
      const std::string was = lookup_mode_name(c.mode);
      const std::string why = format("saves %.0f of %.0f rays a frame (%.2f%%), below 1%%",
                                     saved_rays, frame_rays,
                                     100.0 * saved_rays / std::max(1.0, frame_rays));
      if (c.rung + 1 < kLadderSize) {
        c.set_rung(c.rung + 1);
        c.reason = why + " in " + was + " mode: trying " + lookup_mode_name(c.mode) +
                   format(" (tau %.2f deg)", c.tau_deg);
      } else {
        c.enabled = false;
        c.reason = why + " in every lookup mode: off";
      }
      return;
    }
  }
  if (lookups == 0 && c.frames_in_mode >= 4 && c.valid == 0) {
    // Nothing leaves it towards anything: it can only cost.
    c.enabled = false;
    c.reason = "no leaving rays to serve: off";
  }
}

void RayCacheStore::fold_incoming() {
  // Each sampled cell joins its moving average (α = kProbeDecay, as the probes' texels); the
  // irradiance follows.
  for (auto& cp : cubes_) {
    Cube& c = *cp;
    if (c.incoming_batch.empty()) continue;
    const std::size_t cells = c.incoming_batch.size() / 4;
    if (c.incoming.size() != cells) c.incoming.assign(cells, IncomingCell{});
    bool any = false;
    for (std::size_t i = 0; i < cells; ++i) {
      const std::int64_t* b = &c.incoming_batch[i * 4];
      if (b[3] == 0) continue;
      any = true;
      IncomingCell& cell = c.incoming[i];
      for (int ch = 0; ch < 3; ++ch)
        cell.sum[ch] = cell.sum[ch] * (1.0f - kProbeDecay) + float(double(b[ch]) / kIncomingScale);
      cell.weight = cell.weight * (1.0f - kProbeDecay) + float(b[3]);
    }
    std::fill(c.incoming_batch.begin(), c.incoming_batch.end(), 0);
    if (!any) continue;
    c.near_share =
        float(double(c.near_samples) / double(std::max<std::uint64_t>(1, c.incoming_samples)));
    c.near_samples = c.incoming_samples = 0;
    float coverage = 0.0f;
    c.irradiance = project_irradiance(c.incoming, c.incoming_side(), coverage);
    c.irradiance_ready = coverage >= kIncomingCoverage && c.near_share <= kNearShare;
  }
}

void RayCacheStore::end_frame(double trace_ms, std::uint64_t rays) {
  fold_incoming();
  const std::uint64_t written = apply_writes();
  const double ns_per_ray = rays > 0 ? trace_ms * 1e6 / double(rays) : 0.0;
  CacheCounts& n = counts_;
  n = CacheCounts{};
  n.prefilled = pending_prefilled_;
  pending_prefilled_ = 0;
  n.written = written;
  n.invalidated = last_invalidation_.outdated;
  n.flush_all = last_invalidation_.flush_all;
  for (auto& cp : cubes_) {
    Cube& c = *cp;
    decide(c, ns_per_ray, double(rays));
    n.lookups += c.lookups.load();
    n.hits += c.used;
    n.rejected += c.rejected.load();
    n.verified += c.verified;
    n.texels += c.texels.size();
    n.valid += c.valid;
    n.memory_bytes += c.texels.size() * sizeof(Texel) + c.probe.size() * sizeof(ProbeTexel) +
                      c.incoming.size() * sizeof(IncomingCell) +
                      c.edges.size() * sizeof(std::uint32_t);
    CubeReport r;
    r.entity = c.owner.index;
    r.resolution = c.resolution;
    // Path mode's cubes whose texels do not serve only light their object's diffuse lobe.
    r.mode = !c.enabled                 ? "off"
             : averaging_ && !serving() ? "irradiance"
                                        : lookup_mode_name(c.mode);
    r.reason = c.reason;
    r.lookups = c.lookups.load();
    r.hits = c.used;
    r.valid = c.valid;
    r.estimated_psnr_db = c.estimated_psnr;
    r.saved_ms = c.saved_ms;
    n.cubes.push_back(r);
  }
  last_invalidation_ = InvalidationStats{};
}

} // namespace specula::cache
