// Rays and hits as the Vulkan kernels exchange them (trace_rays.comp, the streaming kernels), and
// the loop-budget counters every kernel keeps (PLATFORM-NOTES: lavapipe silently ends loops past
// 65,535 iterations per dispatch). Included by C++ and GLSL (std430), as scene_layout.h.
#ifndef SPECULA_SHARED_TRACE_LAYOUT_H
#define SPECULA_SHARED_TRACE_LAYOUT_H

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

/// The scene's buffers (GpuScene, shaders/include/trace.glsl) take bindings [0, kSceneBindings) of
/// set 0 in every kernel that traces; a kernel's own buffers follow.
SPECULA_CONST uint kSceneBindings = 8u;

/// A ray (geometry/ray.h's Ray): hits count within (tnear, tfar).
struct GpuRay {
  vec3 origin;
  float tnear;
  vec3 direction;
  float tfar;
};

/// A closest hit (geometry/ray.h's Hit): instance is the SceneTables instance slot, or kNoIndex
/// (scene_layout.h) for a miss; primitive the triangle within the instance's mesh; u, v
/// Embree's barycentrics (u weights vertex 1); ng the geometric normal in mesh space
/// (Hit::object_normal, unnormalised, as the CPU backends give it).
struct GpuHit {
  float t;
  float u;
  float v;
  uint instance;
  uint primitive;
  float ng_x;
  float ng_y;
  float ng_z;
};

/// What a kernel writes in a ray's status word: set only at the kernel's own exits, so a ray whose
/// status is still kRayPending after the dispatch was cut off by the driver (must never happen).
SPECULA_CONST uint kRayPending = 0u;
SPECULA_CONST uint kRayDone = 1u;
/// The ray used up its traversal budget in this dispatch; it is resumed in a later one.
SPECULA_CONST uint kRayBudget = 2u;

/// trace_rays.comp sums its steps into kStepSlots counters, each on a 64-byte line of its own
/// (kStepSlotStride words apart), by workgroup: on llvmpipe an atomic is a locked add, and one
/// counter for all would bounce its cache line between the worker threads at every subgroup.
SPECULA_CONST uint kStepSlots = 32u;
SPECULA_CONST uint kStepSlotStride = 16u;

/// Per-dispatch counters (atomics).
struct TraceCounters {
  uint budget;    ///< rays that used up their budget (resumed)
  uint cut;       ///< rays found still pending after a dispatch: the driver cut a loop (must be 0)
  uint tests;     ///< ray/triangle tests, summed (trace_rays.comp's kCountTests; 0 without it)
  uint _pad0;
  /// Traversal steps (node or cell visits): the sum of steps[k · kStepSlotStride], k < kStepSlots.
  uint steps[kStepSlots * kStepSlotStride];
};

#ifdef __cplusplus
static_assert(sizeof(GpuRay) == 32 && offsetof(GpuRay, direction) == 16 &&
              offsetof(GpuRay, tfar) == 28);
static_assert(sizeof(GpuHit) == 32 && offsetof(GpuHit, instance) == 12 &&
              offsetof(GpuHit, ng_x) == 20);
static_assert(sizeof(TraceCounters) == 16 + 4 * kStepSlots * kStepSlotStride);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_TRACE_LAYOUT_H
