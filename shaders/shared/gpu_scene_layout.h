// The two-level structure as GpuScene lays it out on the device (engine/gpu/gpu_scene.h) and
// shaders/include/trace.glsl walks it. Included by C++ and GLSL (std430), as scene_layout.h.
//
// Bindings 0–3 keep the scene layer's pools as they are (positions, triangles relative to their
// mesh, meshes, instances), so shading kernels read them directly. The traversal adds:
//   4: GpuSceneHeader, then one GpuTopEntry per box of the top level;
//   5: BvhNode[]: the static BVH, each distinct per-mesh BVH, the top level (last); read as a
//      uniform texel buffer of RGBA32UI, two texels a node (GpuScene::texel_bindings);
//   6: uint[]: the static structure's index array (BVH or grid), the grid's cell_start, the static
//      set's first triangle and slot per instance, each per-mesh BVH's index array, the top
//      level's (last);
//   7: uint[]: the traced triangles, their three vertices' positions each (the float bit patterns
//      and a zero word per vertex, copied from the positions pool, so that a triangle test reads
//      no index first): the static set in its structure's order, then each per-mesh BVH's mesh;
//      read as a uniform texel buffer of RGBA32UI, one texel a vertex.
// A tree's node and entry indices are relative to its own bases (the arrays are copied as the CPU
// builders lay them out).
#ifndef SPECULA_SHARED_GPU_SCENE_LAYOUT_H
#define SPECULA_SHARED_GPU_SCENE_LAYOUT_H

#ifdef __cplusplus
#include "specula/shared/accel_layout.h"

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

// GpuSceneHeader::static_kind
SPECULA_CONST uint kStaticNone = 0u;
SPECULA_CONST uint kStaticBvh = 1u;
SPECULA_CONST uint kStaticGrid = 2u;

/// Entries of the traversal stack each invocation keeps (node and entry distance): the static
/// tree's depth, or the top level's depth plus the deepest per-mesh tree's (both below
/// Bvh::kSahDepthLimit + 33 = 81); GpuScene refuses a scene that needs more.
SPECULA_CONST uint kTraceStackSize = 176u;

struct GpuSceneHeader {
  uint instance_count;      ///< slots in the instances table (binding 3)
  uint static_kind;         ///< kStaticNone / Bvh / Grid
  uint static_node_base;    ///< binding 5: root of the static BVH
  uint static_index_base;   ///< binding 6: the static structure's index array
  uint cell_start_base;     ///< binding 6: the grid's cell_start (cell_count + 1 entries)
  uint static_first_base;   ///< binding 6: first static triangle of each static instance
  uint static_slot_base;    ///< binding 6: its instance slot
  uint static_instances;    ///< entries of the two arrays above
  uint top_node_base;       ///< binding 5: root of the top level
  uint top_index_base;      ///< binding 6: the top level's index array
  uint top_count;           ///< boxes in the top level (0: no dynamic instance)
  float box_far_scale;      ///< accel::kBoxFarScale, from the C++ side so both use the same bits
  GridHeader grid;          ///< the static grid (kStaticGrid)
};

/// A BvhNode as binding 5 holds it: the same fields, the link (index, count) in the second of its
/// two RGBA32UI texels, so that a walk step that needs only the link fetches one texel.
struct GpuNode {
  vec3 bounds_min;
  float max_x;
  float max_y;
  float max_z;
  uint index; ///< BvhNode::index
  uint count; ///< BvhNode::count
};

/// One box of the top level: the instance it holds and where its per-mesh BVH lies.
/// object_from_world's columns c0..c3 (as glm stores them; the fourth row is 0 0 0 1).
struct GpuTopEntry {
  vec3 c0;
  uint slot;       ///< instance slot (Hit::instance)
  vec3 c1;
  uint node_base;  ///< binding 5: root of its BVH
  vec3 c2;
  uint index_base; ///< binding 6: its BVH's index array
  vec3 c3;
  uint tri_base;   ///< binding 7: triangle 0 of its mesh
  uint identity;   ///< 1: the world ray is used as is (world_from_object == identity)
  uint _pad0;
  uint _pad1;
  uint _pad2;
};

/// A ray's traversal state between dispatches of trace_rays.comp (its stack entries are saved
/// beside it): where the walk stands and the closest hit so far.
struct GpuTraceState {
  uint phase;        ///< trace.glsl's kPhase*
  uint node;         ///< next node to visit (absolute), or kNoIndex: pop the stack
  uint leaf_cursor;  ///< next entry of the leaf (or grid cell) being tested
  uint leaf_end;
  uint entry;        ///< top-level box whose BVH is being walked, or kNoIndex
  uint floor;        ///< stack depth at which that BVH's entries start
  uint sp;           ///< stack depth
  uint cells;        ///< grid cells visited (the DDA's step bound)
  int cell_x;
  int cell_y;
  int cell_z;
  float tfar;        ///< the world ray's interval end (shrunk by hits)
  float s_next_x;
  float s_next_y;
  float s_next_z;
  float hit_t;
  float hit_u;
  float hit_v;
  uint hit_instance; ///< slot, kNoIndex (none yet) or kStaticHit (resolved at the end)
  uint hit_tri;      ///< binding 7 triangle of the hit
  uint hit_prim;     ///< triangle within the structure (static) or the mesh (dynamic)
  uint _pad0;
  uint _pad1;
  uint _pad2;
};

#ifdef __cplusplus
static_assert(sizeof(GpuSceneHeader) == 96 && offsetof(GpuSceneHeader, grid) == 48);
static_assert(sizeof(GpuTopEntry) == 80 && offsetof(GpuTopEntry, c1) == 16 &&
              offsetof(GpuTopEntry, c3) == 48 && offsetof(GpuTopEntry, identity) == 64);
static_assert(sizeof(GpuTraceState) == 96 && offsetof(GpuTraceState, cell_x) == 32 &&
              offsetof(GpuTraceState, s_next_x) == 48 && offsetof(GpuTraceState, hit_u) == 64);
static_assert(sizeof(GpuNode) == 32 && offsetof(GpuNode, index) == 24);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_GPU_SCENE_LAYOUT_H
