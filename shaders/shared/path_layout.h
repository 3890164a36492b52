// Path and shadow frames on the device (engine/gpu/device_path.h): their parameters, path records
// and emitter table. Included by C++ and GLSL (std430), as frame_layout.h; the frame kernels'
// bindings 0-22 keep their meaning (binding 15 holds paths, 16 their hits, 17 the path queues).
#ifndef SPECULA_SHARED_PATH_LAYOUT_H
#define SPECULA_SHARED_PATH_LAYOUT_H

#ifdef __cplusplus
#include <glm/glm.hpp>

#include <cstddef>
#include <cstdint>

namespace specula::gpu {
using uint = std::uint32_t;
using vec3 = glm::vec3;
#define SPECULA_CONST inline constexpr
#else
#define SPECULA_CONST const
#endif

/// After the cache's bindings 20-22 (cache_layout.h), which path frames bind to placeholders.
SPECULA_CONST uint kPathParamsBinding = 23u;
SPECULA_CONST uint kPathEmittersBinding = 24u;  ///< EmitterTriangle, as render/emitters.h
SPECULA_CONST uint kPathEmitterFirstBinding = 25u; ///< per instance slot: its first emitter
SPECULA_CONST uint kPathSumsBinding = 26u;      ///< per pixel: the sum of its finished samples
SPECULA_CONST uint kPathSobolBinding = 27u;     ///< sampler.h's byte tables, 4 × 4 × 256
SPECULA_CONST uint kPathBindings = 28u;
/// After the state pools (frame_layout.h): per pixel, the denoiser's guides (GpuGuide).
SPECULA_CONST uint kPathGuidesBinding = 30u;

/// Sampler.h's LightSampling, as the kernels test it.
SPECULA_CONST uint kSamplingMis = 0u;
SPECULA_CONST uint kSamplingBsdf = 1u;
SPECULA_CONST uint kSamplingLight = 2u;

/// Per chunk of paths. Path i of a chunk is pixel first_pixel + i / batch, sample
/// sample_offset + first_sample + i % batch of it.
struct GpuPathParams {
  uint path_count;
  uint batch;
  uint first_pixel;
  uint first_sample; ///< of this batch, relative to sample_offset
  uint sample_offset;
  uint seed;
  uint spp;          ///< path: samples per pixel of the frame (shadow: 1)
  uint shadow_samples;
  uint shadow_slots; ///< per path: light count + 1 (path) or + shadow_samples (shadow)
  uint emitter_count;
  uint last_batch;   ///< 1: the resolve writes the image
  uint _pad0;
};

/// One path (path mode) or one pixel's primary ray (shadow mode). Its ray is traced by
/// path_trace, its hit shaded by path_shade (or shadow_shade), which adds emission to radiance,
/// writes its shadow rays to its own slots and, to continue, its next ray; path_gather then adds
/// the visible shadow rays in the order they were written, as the CPU's trace_shadows does.
struct GpuPath {
  vec3 origin;
  float tfar;
  vec3 direction;
  uint pixel;
  vec3 throughput;
  uint sample_index; ///< in the pixel's sequence
  vec3 radiance;
  float bsdf_pdf; ///< of the sampled direction (0: camera or specular)
  vec3 previous;  ///< the vertex the ray left
  uint status;    ///< kRayPending / kRayDone / kRayBudget, set only at path_trace's exits
  uint depth;     ///< of the vertex its ray will hit
  uint kind;      ///< RayKind counted when traced; kKindUncounted: a pixel's further primaries
  uint alive;     ///< 0: ended (no ray to trace)
  uint shadow_count;
};

/// The denoiser's guides of one pixel (image/denoise.h's GuideBuffers, integrators.h's
/// write_guide): at its primary hit, the albedo (diffuse colour, specular parts white), the
/// distance and the shading normal; a miss: albedo 1, depth +inf, normal 0.
struct GpuGuide {
  vec3 albedo;
  float depth;
  vec3 normal;
  float _pad0;
};

/// render/emitters.h's EmitterTriangle (uploaded as is).
struct GpuEmitter {
  vec3 p0;
  float area;
  vec3 e1;
  float cdf;
  vec3 e2;
  float pick;
  vec3 normal;
  uint instance;
  vec3 emission;
  uint primitive;
};

SPECULA_CONST uint kKindUncounted = 4u;

#ifdef __cplusplus
static_assert(sizeof(GpuPathParams) == 48);
static_assert(sizeof(GpuPath) == 96 && offsetof(GpuPath, previous) == 64 &&
              offsetof(GpuPath, depth) == 80);
static_assert(sizeof(GpuGuide) == 32 && offsetof(GpuGuide, normal) == 16);
static_assert(sizeof(GpuEmitter) == 80 && offsetof(GpuEmitter, normal) == 48 &&
              offsetof(GpuEmitter, emission) == 64);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_PATH_LAYOUT_H
