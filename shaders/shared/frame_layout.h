// Whole frames on the device (engine/gpu/device_renderer.h): the streaming kernels' parameters,
// ray records and counters. Included by C++ and GLSL (std430), as scene_layout.h.
#ifndef SPECULA_SHARED_FRAME_LAYOUT_H
#define SPECULA_SHARED_FRAME_LAYOUT_H

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

/// The frame kernels' own buffers follow the scene's (kSceneBindings = 8).
SPECULA_CONST uint kFrameParamsBinding = 8u;
SPECULA_CONST uint kFrameMaterialsBinding = 9u;
SPECULA_CONST uint kFrameLightsBinding = 10u;
SPECULA_CONST uint kFrameNormalsBinding = 11u;
SPECULA_CONST uint kFrameCountersBinding = 12u;
SPECULA_CONST uint kFrameImageBinding = 13u;
SPECULA_CONST uint kFramePrimaryBinding = 14u;
/// Wavefront: nodes, hits, ray queues (2 × capacity), shadow rays, shadow queues.
SPECULA_CONST uint kFrameNodesBinding = 15u;
SPECULA_CONST uint kFrameHitsBinding = 16u;
SPECULA_CONST uint kFrameQueuesBinding = 17u;
SPECULA_CONST uint kFrameShadowsBinding = 18u;
SPECULA_CONST uint kFrameShadowQueuesBinding = 19u;
SPECULA_CONST uint kFrameBindings = 20u;
/// Bindings 20-22: the ray-cache cubes (cache_layout.h), bound in every frame (placeholders
/// without cubes). 23-27 belong to one family of kernels or the other: path frames
/// (path_layout.h), or hybrid mode's (frame_visibility.comp, frame_single.comp) 23-24: the
/// visibility buffer (per pixel the instance slot and triangle rasterised, kNoIndex: none) and,
/// per instance slot, its top-level box (kNoIndex: static).
SPECULA_CONST uint kFrameVisibilityBinding = 23u;
SPECULA_CONST uint kFrameSlotBoxesBinding = 24u;
/// Saved traversal states (trace_pool.glsl): GpuTraceState per slot and params.stack_stride stack
/// entries per slot, after both families' bindings so that frame_shadow.comp serves both
/// renderers; every frame and path pipeline has kFramePoolBindings (binding 30: the path frames'
/// denoiser guides, path_layout.h's kPathGuidesBinding; 31: the ray-cache cubes' counts,
/// cache_layout.h's kCacheCountsBinding).
SPECULA_CONST uint kFramePoolStatesBinding = 28u;
SPECULA_CONST uint kFramePoolStacksBinding = 29u;
SPECULA_CONST uint kFramePoolBindings = 32u;

/// Single kernel: stack frames per pixel. A pixel's Whitted tree is walked depth first, so it
/// needs max_depth + 1 frames; children deeper than the stack are not traced and counted as
/// dropped (DeviceRenderer::supports keeps max_depth below it in practice: it is reported).
SPECULA_CONST uint kStackFrames = 8u;

/// Wavefront: the node count marked before each of the first kWaveMarks waves
/// (GpuFrameCounters::wave_nodes). The fold of depth d ≥ 1 covers only the nodes from the mark of
/// wave d − 1 on: a depth-d node is spawned by shading a depth-(d − 1) ray, traced in wave d − 1 at
/// the earliest. kMaxTraceDepth (scene.h) is 64, so every depth has its mark.
SPECULA_CONST uint kWaveMarks = 64u;

/// Per frame, uploaded once (binding kFrameParamsBinding). Camera in render space as
/// trace/camera_rays.h computes it on the CPU.
struct GpuFrameParams {
  vec3 camera_origin;
  uint width;
  vec3 camera_forward;
  uint height;
  vec3 camera_right;
  float inv_width;
  vec3 camera_up;
  float inv_height;
  vec3 background;
  float min_weight;
  uint max_depth;
  uint light_count;
  uint node_capacity;   ///< wavefront: entries of the node buffer
  uint shadow_capacity; ///< wavefront: entries of the shadow buffer
  uint budget;          ///< traversal iterations an invocation may use in one dispatch
  uint pixel_count;
  uint first_pixel; ///< the chunk's first pixel (single kernel; a wavefront frame in chunks)
  uint chunk_pixels;
  uint record_capacity; ///< ray-cache records (cache_layout.h) the frame may write
  uint stack_stride;    ///< saved stack entries per pool slot (GpuScene::stack_depth)
  uint pool_slots;      ///< slots per state pool (wavefront: two pools; single kernel: one)
  uint _pad2;
};

/// One ray of a pixel's Whitted tree (wavefront). Its radiance is first its local shading's
/// starting value (emission, or the background on a miss); the fold adds its visible shadow
/// rays' values in light order, then its refraction and reflection children × their weights, as
/// the CPU's WhittedTile::fold does.
struct GpuFrameNode {
  vec3 origin;
  float tfar;
  vec3 direction;
  uint pixel;
  vec3 throughput;
  uint depth;
  vec3 radiance;
  float weight; ///< relative to the parent
  uint kind;    ///< RayKind
  uint status;  ///< kRayPending / kRayDone / kRayBudget (trace), set only at the kernel's exits
  uint child_reflect;
  uint child_refract;
  uint shadow_first;
  uint shadow_count;
  // Ray-cache cubes (kCache): what the CPU hands the store for a leaving ray (LeavingRadiance).
  uint seen;   ///< entity bits its subtree hit (folded)
  uint rays;   ///< rays traced for it and its subtree (folded)
  uint leaves; ///< the slot whose cube gets its record (kNoIndex: none)
  uint answer; ///< kAnswer* | kAnswerLookedUp (frame_cache.glsl)
  uint resume; ///< while kRayBudget: the pool slot of its saved walk (kNoIndex: starts over)
  uint _pad1;
};

/// A shadow ray and what it brings when nothing blocks it (wavefront).
struct GpuShadowRay {
  vec3 origin;
  float tfar;
  vec3 direction;
  uint status; ///< kRayPending / kRayDone / kRayBudget
  vec3 value;
  uint visible; ///< 1: counts (not blocked, or not traced because shadows are off); while
                ///< kRayBudget: the pool slot of its saved walk (kNoIndex: starts over)
};

/// One level of a pixel's depth-first walk (single kernel): the ray, and once it is shaded what
/// its shadow rays and children need, so that a walk cut by the traversal budget resumes in the
/// next dispatch exactly where it stopped.
struct GpuStackFrame {
  vec3 origin;
  uint state; ///< kFrame* below
  vec3 direction;
  uint depth;
  vec3 throughput;
  float weight;
  vec3 radiance;
  uint light; ///< next light whose shadow ray is due
  vec3 position;
  uint kind;
  vec3 shadow_origin;
  float reflect_weight;
  vec3 geometric_normal;
  float refract_weight;
  vec3 shading_normal;
  uint seen; ///< ray-cache cubes (kCache): as GpuFrameNode's
  vec3 albedo;
  uint rays;
  vec3 reflect_origin;
  uint hit_entity;
  vec3 reflect_direction;
  float hit_t;
  vec3 refract_origin;
  uint leaves;
  vec3 refract_direction;
  uint answer;
  uint reflect_leaves; ///< the children's `leaves`, found when this frame is shaded
  uint refract_leaves;
  uint resume; ///< 1: the trace of its current state stopped on the budget and was saved
  uint _pad1;
};

SPECULA_CONST uint kFrameTrace = 0u;   ///< its ray is to be traced and shaded
SPECULA_CONST uint kFrameShadows = 1u; ///< shaded; shadow rays from `light` on are due
SPECULA_CONST uint kFrameRefract = 2u; ///< shadows done; the refraction child is next
SPECULA_CONST uint kFrameReflect = 3u; ///< the reflection child is next
SPECULA_CONST uint kFrameReturn = 4u;  ///< complete: folds into its parent
SPECULA_CONST uint kFrameConfirm = 5u; ///< a cached miss: its occlusion ray is due

/// Indirect dispatch arguments.
struct GpuDispatch {
  uint x;
  uint y;
  uint z;
};

/// Counters of a frame (atomics), read back at its end.
struct GpuFrameCounters {
  GpuDispatch ray_args;
  uint node_count;
  GpuDispatch shadow_args;
  uint shadow_count;
  uint queue_count[2];        ///< wavefront ray queues (ping-pong by wave)
  uint shadow_queue_count[2]; ///< wavefront shadow queues
  uint rays[4];               ///< traced rays by RayKind
  uint resumed;  ///< traces that used up a dispatch's budget and were resumed
  uint cut;      ///< rays found pending after a dispatch: the driver cut a loop (must be 0)
  uint dropped;  ///< rays not traced: node or shadow buffer full, or the stack full
  uint nonfinite; ///< pixels that came out Inf or NaN (written as 0)
  uint pending;   ///< single kernel: pixels not finished after a dispatch (resumed)
  uint records;   ///< ray-cache records written (past GpuFrameParams::record_capacity: lost)
  uint retraced;  ///< hybrid: primary rays traced after all (instance boundaries, raster misses)
  uint state_count[2]; ///< wavefront: slots taken in each state pool (by wave parity)
  uint restarted; ///< traces out of budget that found their pool full: they start over
  uint _pad0;
  uint _pad1;
  uint wave_nodes[kWaveMarks]; ///< wavefront: node_count (≤ capacity) before wave w's shading
};

#ifdef __cplusplus
static_assert(sizeof(GpuFrameParams) == 128 && offsetof(GpuFrameParams, background) == 64 &&
              offsetof(GpuFrameParams, max_depth) == 80);
static_assert(sizeof(GpuFrameNode) == 112 && offsetof(GpuFrameNode, kind) == 64);
static_assert(sizeof(GpuShadowRay) == 48);
static_assert(sizeof(GpuStackFrame) == 224 && offsetof(GpuStackFrame, refract_direction) == 192);
static_assert(sizeof(GpuFrameCounters) == 112 + 4 * kWaveMarks &&
              offsetof(GpuFrameCounters, queue_count) == 32 &&
              offsetof(GpuFrameCounters, rays) == 48);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_FRAME_LAYOUT_H
