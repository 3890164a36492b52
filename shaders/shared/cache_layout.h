// Ray-cache cubes on the device (engine/gpu/device_cache.h): the cube table, the texels and the
// leaving-ray records the frame kernels write. Included by C++ and GLSL (std430).
#ifndef SPECULA_SHARED_CACHE_LAYOUT_H
#define SPECULA_SHARED_CACHE_LAYOUT_H

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

/// After the frame kernels' own buffers (frame_layout.h, kFrameBindings = 20).
SPECULA_CONST uint kCacheCubesBinding = 20u;
SPECULA_CONST uint kCacheTexelsBinding = 21u;
SPECULA_CONST uint kCacheRecordsBinding = 22u;
SPECULA_CONST uint kCacheBindings = 23u;
/// Per instance slot, kCubeCountWords words of what the frame's lookups and unrecorded leaving
/// rays added to its cube (kCount* below): after the pool and guide bindings
/// (frame_layout.h's kFramePoolBindings - 1).
SPECULA_CONST uint kCacheCountsBinding = 31u;

/// GpuCube::mode: cache::LookupMode (Direction, Tau, March); kCubeNone: the slot has no cube.
SPECULA_CONST uint kCubeDirection = 0u;
SPECULA_CONST uint kCubeTau = 1u;
SPECULA_CONST uint kCubeMarch = 2u;
/// The march's bounds (ray_cache.cpp): steps along the ray, then bisection steps. A lookup in
/// march mode runs at most kCubeMarchIterations loop iterations (the single kernel charges them
/// to its traversal budget: lavapipe's loop cap).
SPECULA_CONST uint kCubeMarchSteps = 96u;
SPECULA_CONST uint kCubeRefineSteps = 6u;
SPECULA_CONST uint kCubeMarchIterations = kCubeMarchSteps + kCubeRefineSteps;
SPECULA_CONST uint kCubeNone = 0xFFFFFFFFu;
/// GpuCube::flags.
SPECULA_CONST uint kCubeEnabled = 1u; ///< looked up (else only its leaving rays are recorded)
/// Every leaving ray is recorded, looked up or served, and the host replays the lookups on the
/// store (DeviceCache::Records::every, checked against the kernels' counts). Without it, only
/// rays that may change the store are recorded (a traced ray whose texel is outdated: a write;
/// a verified one: an error sample), and the rest are counted in the kernels.
SPECULA_CONST uint kCubeRecordAll = 2u;

/// A slot's words in the counts buffer (kCacheCountsBinding): 32-bit counts, and 64-bit sums as
/// two words, low first (the kernels carry into the high word).
SPECULA_CONST uint kCountLookups = 0u;
SPECULA_CONST uint kCountOutdated = 1u;
SPECULA_CONST uint kCountRejected = 2u;
SPECULA_CONST uint kCountUsed = 3u;        ///< served leaving rays (CacheAnswer Use / UseIfClear)
SPECULA_CONST uint kCountTraced = 4u;      ///< traced leaving rays that wrote nothing
SPECULA_CONST uint kCountSteps = 6u;       ///< march steps (64-bit, words 6-7)
SPECULA_CONST uint kCountOffered = 8u;     ///< what the served texels cost when traced (64-bit)
SPECULA_CONST uint kCountUsedRays = 10u;   ///< rays the served leaving rays traced (64-bit)
SPECULA_CONST uint kCountTracedRays = 12u; ///< rays of the unrecorded traced ones (64-bit)
SPECULA_CONST uint kCubeCountWords = 16u;

/// How a leaving ray was served (CacheAnswer's values), and a lookup's first answer.
SPECULA_CONST uint kAnswerTrace = 0u;
SPECULA_CONST uint kAnswerUse = 1u;
SPECULA_CONST uint kAnswerUseIfClear = 2u;
SPECULA_CONST uint kAnswerVerify = 3u; ///< auto: it would be used, but is traced to measure the error
/// The frame kernels' answer word: the answer, kAnswerLookedUp (16) and, from this bit up, the
/// texel the lookup read (so a cube has at most 2^27 texels: faces up to 4096² and beyond).
SPECULA_CONST uint kAnswerTexelShift = 5u;

/// One cube per scene-layer instance slot (mode kCubeNone where the slot has none).
struct GpuCube {
  vec3 centre;
  uint resolution;
  uint first_texel; ///< into the texel buffer (uvec4 per cache::Texel)
  uint mode;
  float cos_tau;
  uint flags;
  uint verify_every; ///< auto: cache::verify_chosen's period (0: no lookup is verified)
  uint index;        ///< the cube's index in the store (verify_chosen hashes it)
  uint frame;        ///< the store's verify_frame()
  float cos_half_texel; ///< March: cos(½ · 2/resolution), the march's "within a texel of d"
};

/// A ray that left a cached object (the CPU's LeavingRadiance, for the cube's rays only):
/// written by the frame kernels once its subtree is folded, read back after the frame.
struct GpuLeavingRecord {
  vec3 origin;
  uint instance; ///< the slot it leaves
  vec3 direction;
  uint pixel;
  vec3 radiance;
  float hit_t;     ///< +inf: it left the scene (or was served)
  uint hit_entity; ///< kNoIndex: none
  uint seen;
  uint rays;
  uint packed; ///< depth | kind << 8 | answer << 12 | looked up << 16
  vec3 throughput; ///< relative to the pixel (a verified ray's error is weighed by it)
  uint texel; ///< the texel its lookup read, in its cube (a verified ray's error is against it)
};

#ifdef __cplusplus
static_assert(sizeof(GpuCube) == 48);
static_assert(sizeof(GpuLeavingRecord) == 80 && offsetof(GpuLeavingRecord, throughput) == 64);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_CACHE_LAYOUT_H
