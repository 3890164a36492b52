// Flat layouts of Specula's own acceleration structures, shared by the CPU backend (engine/accel)
// and the Vulkan path: 32-bit indices, no pointers, each structure one contiguous array of nodes
// plus one array of triangle indices. Included by C++ and by GLSL (std430 rules as in
// scene_layout.h); the C++ side checks sizes and offsets with static_assert.
#ifndef SPECULA_SHARED_ACCEL_LAYOUT_H
#define SPECULA_SHARED_ACCEL_LAYOUT_H

#ifdef __cplusplus
#include <glm/glm.hpp>

#include <cstddef>
#include <cstdint>

namespace specula::gpu {
using uint = std::uint32_t;
using uvec3 = glm::uvec3;
using vec3 = glm::vec3;
#define SPECULA_CONST inline constexpr
#else
#define SPECULA_CONST const
#endif

// ---- SAH kd-tree: 8-byte nodes (Wald & Havran 2006; the layout of pbrt's KdAccelNode) ----------
// bits [0, 2) of `bits`: the split axis (0, 1, 2) of an interior node, or 3 for a leaf.
// Interior: `bits >> 2` is the index of the child above the split (the child below is the next
// node), `split` the plane's position. Leaf: `bits >> 2` is its triangle count and `split` holds,
// as bits (floatBitsToUint in GLSL), the offset of its first entry in the triangle index array.
SPECULA_CONST uint kKdLeaf = 3u;

struct KdNode {
#ifdef __cplusplus
  uint bits;
  union {
    float split;
    uint first;
  };
#else
  uint bits;
  uint split_or_first; // uintBitsToFloat for an interior node's split
#endif
};

// ---- BVH: 32-byte nodes --------------------------------------------------------------------------
// count == 0: interior node whose children are nodes `index` and `index + 1`.
// count in [1, kBvhUnbuilt): leaf holding entries [index, index + count) of the index array.
// count & kBvhUnbuilt: a lazily built subtree not expanded yet, over the same entry range (CPU
// only: the GPU path never sees an unbuilt node).
SPECULA_CONST uint kBvhUnbuilt = 0x80000000u;

struct BvhNode {
  vec3 bounds_min;
  uint index;
  vec3 bounds_max;
  uint count;
};

// ---- Uniform grid (Purcell et al. 2002; Amanatides & Woo 1987 3D-DDA) ---------------------------
// Cubical voxels of side cell_size from bounds_min, resolution cells along each axis. Cell
// c = x + resolution.x · (y + resolution.y · z) lists entries [cell_start[c], cell_start[c + 1])
// of the triangle index array (cell_start has cell count + 1 entries).
struct GridHeader {
  vec3 bounds_min;
  float cell_size;
  uvec3 resolution;
  uint cell_count;
  vec3 bounds_max;
  float inv_cell_size;
};

#ifdef __cplusplus
static_assert(sizeof(KdNode) == 8 && offsetof(KdNode, split) == 4);
static_assert(sizeof(BvhNode) == 32 && offsetof(BvhNode, index) == 12 &&
              offsetof(BvhNode, bounds_max) == 16 && offsetof(BvhNode, count) == 28);
static_assert(sizeof(GridHeader) == 48 && offsetof(GridHeader, resolution) == 16 &&
              offsetof(GridHeader, bounds_max) == 32);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_ACCEL_LAYOUT_H
