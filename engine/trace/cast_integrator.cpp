// Cast mode: local shading of the primary hits, no shadow or secondary rays, over the tile's wave
// of hits in SoA. Two stages: a gather that turns each hit into world-space shading inputs (one
// array per quantity), then the lights, one light at a time over the whole wave with no branch
// per hit, which the compiler vectorises (and, through target_clones, runs 8-wide where the CPU
// has AVX2). The arithmetic is that of shading_point and sample_light, in the same order, so the
// image is the one those functions give.

#include "specula/trace/integrators.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"

#include <cmath>
#include <limits>
#include <numbers>

namespace specula::detail {
namespace {

/// Stage 1a: each hit's triangle data, gathered into SoA (scalar: it is all indirect loads).
/// Hits on instances baked in world space (the static set: most hits of most frames) are shaded
/// by the vector kernel below; the others are listed for shading_point.
void gather(const SceneTables& tables, const PrimaryHits& hits, CastWave& w) {
  constexpr float kInvPi = std::numbers::inv_pi_v<float>;
  const std::size_t n = hits.size();
  w.general.clear();
  std::uint32_t current = kNoInstance;
  bool identity = false, smooth = false;
  const vec3* positions = nullptr;
  const vec3* normals = nullptr;
  const uvec3* triangles = nullptr;
  vec3 albedo(0.0f), emission(0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t instance = hits.instance[i];
    if (instance != current && instance != kNoInstance) {
      current = instance;
      const gpu::GpuInstance& inst = tables.instances[instance];
      const gpu::GpuMesh& mesh = tables.meshes[inst.mesh];
      const gpu::GpuMaterial& m = tables.materials[inst.material];
      identity = (inst.flags & gpu::kInstanceIdentity) != 0;
      smooth = (inst.flags & gpu::kInstanceSmooth) != 0 && mesh.first_normal != gpu::kNoIndex;
      positions = tables.positions.data() + mesh.first_vertex;
      normals = smooth ? tables.normals.data() + mesh.first_normal : nullptr;
      triangles = tables.triangles.data() + mesh.first_triangle;
      albedo = m.base_color * kInvPi;
      emission = m.emission;
    }
    const bool baked = instance != kNoInstance && identity;
    w.hit[i] = instance != kNoInstance ? 1u : 0u;
    w.smooth[i] = baked && smooth ? 1u : 0u;
    if (instance != kNoInstance && !identity) w.general.push_back(std::uint32_t(i));
    vec3 p0(0.0f), p1(0.0f), p2(0.0f), n0(0.0f), n1(0.0f), n2(0.0f);
    if (baked) {
      const uvec3 tri = triangles[hits.primitive[i]];
      p0 = positions[tri.x];
      p1 = positions[tri.y];
      p2 = positions[tri.z];
      if (smooth) {
        n0 = normals[tri.x];
        n1 = normals[tri.y];
        n2 = normals[tri.z];
      }
    }
    w.p0x[i] = p0.x, w.p0y[i] = p0.y, w.p0z[i] = p0.z;
    w.p1x[i] = p1.x, w.p1y[i] = p1.y, w.p1z[i] = p1.z;
    w.p2x[i] = p2.x, w.p2y[i] = p2.y, w.p2z[i] = p2.z;
    w.n0x[i] = n0.x, w.n0y[i] = n0.y, w.n0z[i] = n0.z;
    w.n1x[i] = n1.x, w.n1y[i] = n1.y, w.n1z[i] = n1.z;
    w.n2x[i] = n2.x, w.n2y[i] = n2.y, w.n2z[i] = n2.z;
    const bool hit = instance != kNoInstance;
    w.ar[i] = hit ? albedo.x : 0.0f;
    w.ag[i] = hit ? albedo.y : 0.0f;
    w.ab[i] = hit ? albedo.z : 0.0f;
    w.lr[i] = hit ? emission.x : 0.0f;
    w.lg[i] = hit ? emission.y : 0.0f;
    w.lb[i] = hit ? emission.z : 0.0f;
  }
}

/// Stage 1b: shading_point(…, with_error_bound = false) for baked instances, over the whole wave
/// with no branch per hit — the same operations in the same order (GLM's normalize is
/// v · (1 / sqrt(v·v)), its dot ((x + y) + z)).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) &&                             \
    !defined(__SANITIZE_ADDRESS__)
__attribute__((target_clones("avx2", "default")))
#endif
void shading_kernel(std::size_t n, const float* __restrict u_, const float* __restrict v_,
                    const float* __restrict ngx, const float* __restrict ngy, const float* __restrict ngz,
                    const float* __restrict dx, const float* __restrict dy, const float* __restrict dz,
                    const float* __restrict p0x, const float* __restrict p0y, const float* __restrict p0z,
                    const float* __restrict p1x, const float* __restrict p1y, const float* __restrict p1z,
                    const float* __restrict p2x, const float* __restrict p2y, const float* __restrict p2z,
                    const float* __restrict n0x, const float* __restrict n0y, const float* __restrict n0z,
                    const float* __restrict n1x, const float* __restrict n1y, const float* __restrict n1z,
                    const float* __restrict n2x, const float* __restrict n2y, const float* __restrict n2z,
                    const std::uint32_t* __restrict smooth, float* __restrict px, float* __restrict py,
                    float* __restrict pz, float* __restrict gx, float* __restrict gy, float* __restrict gz,
                    float* __restrict sx, float* __restrict sy, float* __restrict sz) {
  constexpr float kLargest = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < n; ++i) {
    const float u = u_[i], v = v_[i];
    const float b0 = 1.0f - u - v;
    px[i] = b0 * p0x[i] + u * p1x[i] + v * p2x[i];
    py[i] = b0 * p0y[i] + u * p1y[i] + v * p2y[i];
    pz[i] = b0 * p0z[i] + u * p1z[i] + v * p2z[i];
    const float inv = 1.0f / std::sqrt(ngx[i] * ngx[i] + ngy[i] * ngy[i] + ngz[i] * ngz[i]);
    const float nx = ngx[i] * inv, ny = ngy[i] * inv, nz = ngz[i] * inv;
    const bool front = nx * dx[i] + ny * dy[i] + nz * dz[i] < 0.0f;
    const float g_x = front ? nx : -nx, g_y = front ? ny : -ny, g_z = front ? nz : -nz;
    const float mx = b0 * n0x[i] + u * n1x[i] + v * n2x[i];
    const float my = b0 * n0y[i] + u * n1y[i] + v * n2y[i];
    const float mz = b0 * n0z[i] + u * n1z[i] + v * n2z[i];
    const float len = std::sqrt(mx * mx + my * my + mz * mz);
    const float s_x = mx / len, s_y = my / len, s_z = mz / len;
    const bool flip = s_x * g_x + s_y * g_y + s_z * g_z < 0.0f;
    // len in (0, max]: positive and finite (NaN fails both).
    const bool use = (smooth[i] != 0) & (len > 0.0f) & (len <= kLargest);
    gx[i] = g_x, gy[i] = g_y, gz[i] = g_z;
    sx[i] = use ? (flip ? -s_x : s_x) : g_x;
    sy[i] = use ? (flip ? -s_y : s_y) : g_y;
    sz[i] = use ? (flip ? -s_z : s_z) : g_z;
  }
}

void shade_points(const SceneTables& tables, const PrimaryHits& h, CastWave& w) {
  shading_kernel(h.size(), h.u.data(), h.v.data(), h.ng_x.data(), h.ng_y.data(), h.ng_z.data(),
                 h.dir_x.data(), h.dir_y.data(), h.dir_z.data(), w.p0x.data(), w.p0y.data(),
                 w.p0z.data(), w.p1x.data(), w.p1y.data(), w.p1z.data(), w.p2x.data(), w.p2y.data(),
                 w.p2z.data(), w.n0x.data(), w.n0y.data(), w.n0z.data(), w.n1x.data(), w.n1y.data(),
                 w.n1z.data(), w.n2x.data(), w.n2y.data(), w.n2z.data(), w.smooth.data(),
                 w.px.data(), w.py.data(), w.pz.data(), w.gx.data(), w.gy.data(), w.gz.data(),
                 w.sx.data(), w.sy.data(), w.sz.data());
  // Transformed instances (moving objects): shading_point itself.
  for (const std::uint32_t i : w.general) {
    const ShadingPoint sp = shading_point(tables, h.hit(i), h.direction(i), false);
    w.px[i] = sp.position.x, w.py[i] = sp.position.y, w.pz[i] = sp.position.z;
    w.gx[i] = sp.geometric_normal.x, w.gy[i] = sp.geometric_normal.y,
    w.gz[i] = sp.geometric_normal.z;
    w.sx[i] = sp.shading_normal.x, w.sy[i] = sp.shading_normal.y, w.sz[i] = sp.shading_normal.z;
  }
}

/// Stage 2 for one point light without range or cone, the common case: sample_light's point
/// branch and the cast integrator's tests, branch-free over the wave. Arrays as restrict
/// parameters (restrict locals defeat GCC 12's vectoriser); 8-wide where the CPU has AVX2.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) &&                             \
    !defined(__SANITIZE_ADDRESS__)
__attribute__((target_clones("avx2", "default")))
#endif
void point_light_kernel(std::size_t n, float lx, float ly, float lz, float ir, float ig, float ib,
                        const std::uint32_t* __restrict hit, const float* __restrict px,
                        const float* __restrict py, const float* __restrict pz, const float* __restrict gx,
                        const float* __restrict gy, const float* __restrict gz, const float* __restrict sx,
                        const float* __restrict sy, const float* __restrict sz, const float* __restrict ar,
                        const float* __restrict ag, const float* __restrict ab, float* __restrict lr,
                        float* __restrict lg, float* __restrict lb) {
  for (std::size_t i = 0; i < n; ++i) {
    const float dx = lx - px[i], dy = ly - py[i], dz = lz - pz[i];
    const float dist2 = dx * dx + dy * dy + dz * dz;
    const float dist = std::sqrt(dist2);
    const float tx = dx / dist, ty = dy / dist, tz = dz / dist;
    const float attenuation = 1.0f / dist2;
    const float er = ir * attenuation, eg = ig * attenuation, eb = ib * attenuation;
    const float facing = tx * gx[i] + ty * gy[i] + tz * gz[i];
    const float cos_theta = tx * sx[i] + ty * sy[i] + tz * sz[i];
    const float r = ar[i] * er * cos_theta, g = ag[i] * eg * cos_theta, b = ab[i] * eb * cos_theta;
    const float brightest = er > eg ? (er > eb ? er : eb) : (eg > eb ? eg : eb);
    // dist2 > 0 excludes a point on the light (sample_light returns nothing there). Bitwise and
    // selects, not branches, so that the loop vectorises.
    const bool lit =
        (hit[i] != 0) & (dist2 > 0.0f) & (facing > 0.0f) & (cos_theta > 0.0f) & (brightest > 0.0f);
    lr[i] += lit ? r : 0.0f;
    lg[i] += lit ? g : 0.0f;
    lb[i] += lit ? b : 0.0f;
  }
}

void add_point_light(CastWave& w, std::size_t n, const gpu::GpuLight& light) {
  point_light_kernel(n, light.position.x, light.position.y, light.position.z, light.intensity.x,
                     light.intensity.y, light.intensity.z, w.hit.data(), w.px.data(), w.py.data(),
                     w.pz.data(), w.gx.data(), w.gy.data(), w.gz.data(), w.sx.data(), w.sy.data(),
                     w.sz.data(), w.ar.data(), w.ag.data(), w.ab.data(), w.lr.data(), w.lg.data(),
                     w.lb.data());
}

/// Stage 2 for any other light: sample_light per hit.
void add_light(CastWave& w, std::size_t n, const gpu::GpuLight& light) {
  for (std::size_t i = 0; i < n; ++i) {
    if (w.hit[i] == 0) continue;
    const vec3 p(w.px[i], w.py[i], w.pz[i]);
    const LightSample ls = sample_light(light, p);
    if (glm::dot(ls.to_light, vec3(w.gx[i], w.gy[i], w.gz[i])) <= 0.0f)
      continue; // behind the surface
    const float cos_theta = glm::dot(ls.to_light, vec3(w.sx[i], w.sy[i], w.sz[i]));
    if (cos_theta <= 0.0f || max_component(ls.irradiance) <= 0.0f) continue;
    const vec3 add = vec3(w.ar[i], w.ag[i], w.ab[i]) * ls.irradiance * cos_theta;
    w.lr[i] += add.x;
    w.lg[i] += add.y;
    w.lb[i] += add.z;
  }
}

} // namespace

void cast_tile(const FrameInputs& frame, const PacketTile& tile, TileScratch& scratch,
               RayCounts& counts) {
  const PrimaryHits& hits = scratch.primary;
  CastWave& wave = scratch.cast;
  const std::size_t n = hits.size();
  counts[RayKind::Primary] += n;
  wave.resize(n);
  gather(frame.tables, hits, wave);
  shade_points(frame.tables, hits, wave);
  for (const gpu::GpuLight& light : frame.tables.lights) {
    if (light.type == gpu::kLightPoint && light.range <= 0.0f)
      add_point_light(wave, n, light);
    else
      add_light(wave, n, light);
  }
  const vec3 background = frame.settings.background;
  std::size_t i = 0;
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    const std::size_t k = i++;
    frame.pixels[std::size_t(y) * frame.width + x] =
        wave.hit[k] != 0 ? vec3(wave.lr[k], wave.lg[k], wave.lb[k]) : background;
  });
}

} // namespace specula::detail
