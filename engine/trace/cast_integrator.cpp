// Cast mode: local shading of the primary hits, no shadow or secondary rays, over the tile's wave
// of hits in SoA. Three stages: a gather that interpolates each hit's position and vertex normal
// from its triangle (indirect loads: scalar, instance data looked up once per run of hits); a
// branch-free kernel that turns them into the shading frame; one kernel per light over the whole
// wave. The kernels are vectorised by the compiler (8-wide through target_clones where the CPU has
// AVX2). The arithmetic is shading_point's and sample_light's, in the same order, except that the
// albedo multiplies the sum of the lights' irradiance once, at the end, and that sum is added to
// the emission (tests/trace/test_render.cpp compares every pixel with the plain formula).

#include "specula/trace/integrators.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) &&                             \
    !defined(__SANITIZE_ADDRESS__)
#define SPECULA_SIMD_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define SPECULA_SIMD_CLONES
#endif

namespace specula::detail {
namespace {

constexpr std::uint32_t kBaked = 1u; ///< CastWave::flags: a hit on an instance baked in world space
constexpr std::uint32_t kSmooth = 2u; ///< its vertex normals are interpolated

/// Stage 1: per hit, the barycentric position and vertex normal (b0·v0 + u·v1 + v·v2, as
/// shading_point computes them).
void gather(const SceneTables& tables, const PrimaryHits& hits, CastWave& w) {
  const std::size_t n = hits.size();
  w.general.clear();
  std::uint32_t current = kNoInstance;
  bool identity = false, smooth = false;
  const vec3* positions = nullptr;
  const vec3* normals = nullptr;
  const uvec3* triangles = nullptr;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t instance = hits.instance[i];
    vec3 p(0.0f), m(0.0f);
    std::uint32_t flags = 0;
    if (instance != kNoInstance) {
      if (instance != current) {
        current = instance;
        const gpu::GpuInstance& inst = tables.instances[instance];
        const gpu::GpuMesh& mesh = tables.meshes[inst.mesh];
        identity = (inst.flags & gpu::kInstanceIdentity) != 0;
        smooth = (inst.flags & gpu::kInstanceSmooth) != 0 && mesh.first_normal != gpu::kNoIndex;
        positions = tables.positions.data() + mesh.first_vertex;
        normals = smooth ? tables.normals.data() + mesh.first_normal : nullptr;
        triangles = tables.triangles.data() + mesh.first_triangle;
      }
      if (identity) {
        const uvec3 tri = triangles[hits.primitive[i]];
        const float u = hits.u[i], v = hits.v[i];
        const float b0 = 1.0f - u - v;
        p = b0 * positions[tri.x] + u * positions[tri.y] + v * positions[tri.z];
        flags = kBaked;
        if (smooth) {
          m = b0 * normals[tri.x] + u * normals[tri.y] + v * normals[tri.z];
          flags |= kSmooth;
        }
      } else {
        w.general.push_back(std::uint32_t(i));
      }
    }
    w.px[i] = p.x, w.py[i] = p.y, w.pz[i] = p.z;
    w.sx[i] = m.x, w.sy[i] = m.y, w.sz[i] = m.z;
    w.flags[i] = flags;
  }
}

/// Stage 2: shading_point's frame for baked hits — GLM's normalize is v · (1 / sqrt(v·v)) and its
/// dot ((x + y) + z) — with selects, not branches. (sx, sy, sz) hold the interpolated vertex
/// normal on entry and the shading normal on exit.
SPECULA_SIMD_CLONES
void frame_kernel(std::size_t n, const float* __restrict ngx, const float* __restrict ngy,
                  const float* __restrict ngz, const float* __restrict dx,
                  const float* __restrict dy, const float* __restrict dz,
                  const std::uint32_t* __restrict flags, float* __restrict gx, float* __restrict gy,
                  float* __restrict gz, float* __restrict sx, float* __restrict sy,
                  float* __restrict sz) {
  constexpr float kLargest = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < n; ++i) {
    const float inv = 1.0f / std::sqrt(ngx[i] * ngx[i] + ngy[i] * ngy[i] + ngz[i] * ngz[i]);
    const float nx = ngx[i] * inv, ny = ngy[i] * inv, nz = ngz[i] * inv;
    const bool front = nx * dx[i] + ny * dy[i] + nz * dz[i] < 0.0f;
    const float g_x = front ? nx : -nx, g_y = front ? ny : -ny, g_z = front ? nz : -nz;
    const float mx = sx[i], my = sy[i], mz = sz[i];
    const float len = std::sqrt(mx * mx + my * my + mz * mz);
    const float s_x = mx / len, s_y = my / len, s_z = mz / len;
    const bool flip = s_x * g_x + s_y * g_y + s_z * g_z < 0.0f;
    // len in (0, max]: positive and finite (NaN fails both).
    const bool use = ((flags[i] & kSmooth) != 0) & (len > 0.0f) & (len <= kLargest);
    gx[i] = g_x, gy[i] = g_y, gz[i] = g_z;
    sx[i] = use ? (flip ? -s_x : s_x) : g_x;
    sy[i] = use ? (flip ? -s_y : s_y) : g_y;
    sz[i] = use ? (flip ? -s_z : s_z) : g_z;
  }
}

void shading_frames(const SceneTables& tables, const PrimaryHits& h, CastWave& w) {
  frame_kernel(h.size(), h.ng_x.data(), h.ng_y.data(), h.ng_z.data(), h.dir_x.data(),
               h.dir_y.data(), h.dir_z.data(), w.flags.data(), w.gx.data(), w.gy.data(),
               w.gz.data(), w.sx.data(), w.sy.data(), w.sz.data());
  // Transformed instances (moving objects): shading_point itself.
  for (const std::uint32_t i : w.general) {
    const ShadingPoint sp = shading_point(tables, h.hit(i), h.direction(i), false);
    w.px[i] = sp.position.x, w.py[i] = sp.position.y, w.pz[i] = sp.position.z;
    w.gx[i] = sp.geometric_normal.x, w.gy[i] = sp.geometric_normal.y,
    w.gz[i] = sp.geometric_normal.z;
    w.sx[i] = sp.shading_normal.x, w.sy[i] = sp.shading_normal.y, w.sz[i] = sp.shading_normal.z;
    w.flags[i] = kBaked; // shaded like one from here on
  }
}

/// Stage 3 for one point light without range or cone, the common case: sample_light's point
/// branch (in float: its double d only matters beyond d ≈ 1.8e19, where d² overflows here and the
/// light's contribution, below 1e20 / 3.4e38, is lost) and the integrator's tests, branch-free
/// over the wave; adds irradiance × cos θ.
SPECULA_SIMD_CLONES
void point_light_kernel(std::size_t n, float lx, float ly, float lz, float ir, float ig, float ib,
                        const std::uint32_t* __restrict flags, const float* __restrict px,
                        const float* __restrict py, const float* __restrict pz,
                        const float* __restrict gx, const float* __restrict gy,
                        const float* __restrict gz, const float* __restrict sx,
                        const float* __restrict sy, const float* __restrict sz,
                        float* __restrict lr, float* __restrict lg, float* __restrict lb) {
  for (std::size_t i = 0; i < n; ++i) {
    const float dx = lx - px[i], dy = ly - py[i], dz = lz - pz[i];
    const float dist2 = dx * dx + dy * dy + dz * dz;
    const float dist = std::sqrt(dist2);
    const float tx = dx / dist, ty = dy / dist, tz = dz / dist;
    // sample_light's I / d / d capped at kMaxIrradiance, in float: 1 / d² would flush to zero
    // beyond d ≈ 1e19 (flush-to-zero mode) and I / d² overflow close to a bright light.
    const float inv = 1.0f / dist;
    const float er = std::min(ir * inv * inv, kMaxIrradiance);
    const float eg = std::min(ig * inv * inv, kMaxIrradiance);
    const float eb = std::min(ib * inv * inv, kMaxIrradiance);
    const float facing = tx * gx[i] + ty * gy[i] + tz * gz[i];
    const float cos_theta = tx * sx[i] + ty * sy[i] + tz * sz[i];
    const float r = er * cos_theta, g = eg * cos_theta, b = eb * cos_theta;
    const float brightest = er > eg ? (er > eb ? er : eb) : (eg > eb ? eg : eb);
    // dist2 > 0 excludes a point on the light (sample_light returns nothing there).
    const bool lit = (flags[i] != 0) & (dist2 > 0.0f) & (facing > 0.0f) & (cos_theta > 0.0f) &
                     (brightest > 0.0f);
    lr[i] += lit ? r : 0.0f;
    lg[i] += lit ? g : 0.0f;
    lb[i] += lit ? b : 0.0f;
  }
}

/// Stage 3 for any other light: sample_light per hit.
void add_light(CastWave& w, std::size_t n, const gpu::GpuLight& light) {
  for (std::size_t i = 0; i < n; ++i) {
    if (w.flags[i] == 0) continue;
    const LightSample ls = sample_light(light, vec3(w.px[i], w.py[i], w.pz[i]));
    if (glm::dot(ls.to_light, vec3(w.gx[i], w.gy[i], w.gz[i])) <= 0.0f) continue; // behind
    const float cos_theta = glm::dot(ls.to_light, vec3(w.sx[i], w.sy[i], w.sz[i]));
    if (cos_theta <= 0.0f || max_component(ls.irradiance) <= 0.0f) continue;
    const vec3 add = ls.irradiance * cos_theta;
    w.lr[i] += add.x;
    w.lg[i] += add.y;
    w.lb[i] += add.z;
  }
}

} // namespace

void cast_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
               RayCounts& counts) {
  const SceneTables& tables = frame.tables;
  const PrimaryHits& hits = scratch.primary;
  CastWave& w = scratch.cast;
  const std::size_t n = hits.size();
  counts[RayKind::Primary] += n;
  w.resize(n);
  gather(tables, hits, w);
  shading_frames(tables, hits, w);
  std::fill(w.lr.begin(), w.lr.end(), 0.0f);
  std::fill(w.lg.begin(), w.lg.end(), 0.0f);
  std::fill(w.lb.begin(), w.lb.end(), 0.0f);
  for (const gpu::GpuLight& light : tables.lights) {
    if (light.type == gpu::kLightPoint && light.range <= 0.0f)
      point_light_kernel(n, light.position.x, light.position.y, light.position.z, light.intensity.x,
                         light.intensity.y, light.intensity.z, w.flags.data(), w.px.data(),
                         w.py.data(), w.pz.data(), w.gx.data(), w.gy.data(), w.gz.data(),
                         w.sx.data(), w.sy.data(), w.sz.data(), w.lr.data(), w.lg.data(),
                         w.lb.data());
    else
      add_light(w, n, light);
  }
  // Emission plus albedo × the lights' sum.
  const vec3 background = frame.settings.background;
  std::uint32_t current = kNoInstance;
  vec3 emission(0.0f), albedo(0.0f);
  std::size_t i = 0;
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    const std::size_t k = i++;
    vec3 radiance = background;
    if (const std::uint32_t instance = hits.instance[k]; instance != kNoInstance) {
      if (instance != current) {
        current = instance;
        const gpu::GpuMaterial& m = tables.materials[tables.instances[instance].material];
        emission = m.emission;
        albedo = m.base_color * std::numbers::inv_pi_v<float>;
      }
      radiance = emission + albedo * vec3(w.lr[k], w.lg[k], w.lb[k]);
    }
    frame.pixels[std::size_t(y) * frame.width + x] = finite_or_counted(radiance, counts);
  });
}

} // namespace specula::detail
