// Tracing from any kernel: the scene's buffers at bindings [0, kSceneBindings) of set 0 and the
// two queries every kernel uses.
//
// CONTRACT (kept by every implementation; the streaming kernels rely on it):
//   uint trace_closest(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget,
//                      inout GpuHit hit)
//   uint trace_any(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget,
//                  out bool occluded)
// Both return kRayDone when finished (trace_closest: hit.instance != kNoIndex on a hit; trace_any:
// sets `occluded`) or kRayBudget when
// `budget` (loop iterations left to this invocation in this dispatch) ran out first.
// (kRayPending: the driver cut the walk's loop off; the result is garbage and the ray's status
// must stay unset, so that it is counted as cut.)
//
// Each call starts a fresh traversal. After kRayBudget, trace_closest's `hit` holds the closest hit
// found so far (instance kNoIndex if none): a kernel that cannot keep the traversal state resumes
// with trace_closest_resume (same arguments, same `hit`), which traces again over (tnear, hit.t)
// and keeps the old hit unless a closer one turns up — the result equals an uninterrupted trace
// (up to which of two triangles at exactly the same t wins), but a ray whose walk needs more
// than one dispatch's budget before its first hit makes no progress that way. trace_rays.comp
// instead saves the whole state (trace_state_save / trace_state_load) and loses nothing.
//
// The traversal mirrors the native backend step for step (engine/accel: PreparedRay::make, the
// conservative slab test, Woop et al.'s watertight test with its double fallback, Bvh::traverse,
// UniformGrid's 3D-DDA, NativeTracer's two levels), each operation rounded on its own as in the
// C++ build (common.glsl), so hits are bit-identical to native-bvh / native-grid on the same
// structures. Layout: shaders/shared/gpu_scene_layout.h. One loop iteration per step (a node
// visited, a stack entry popped with the node it leads to, a triangle tested, a grid cell
// entered; a BVH's in two inner loops, trace_run): the budget counts them all, and the state
// between two steps is all there is to save.
#ifndef SPECULA_TRACE_GLSL
#define SPECULA_TRACE_GLSL

#include "shared/scene_layout.h"
#include "shared/trace_layout.h"
#include "shared/accel_layout.h"
#include "shared/gpu_scene_layout.h"
#include "include/ray_triangle.glsl"

layout(std430, set = 0, binding = 0) readonly buffer ScenePositions { float positions[]; };
layout(std430, set = 0, binding = 1) readonly buffer SceneTriangles { uint triangles[]; };
layout(std430, set = 0, binding = 2) readonly buffer SceneMeshes { GpuMesh meshes[]; };
layout(std430, set = 0, binding = 3) readonly buffer SceneInstances { GpuInstance instances[]; };
layout(std430, set = 0, binding = 4) readonly buffer SceneHeader {
  GpuSceneHeader scene_header;
  GpuTopEntry scene_top[];
};
// The nodes and the traced triangles are texel buffers (GpuScene::texel_bindings): llvmpipe
// fetches a texel for all 8 lanes of a SIMD vector with one gather, where it loads a storage
// buffer lane by lane and word by word, each behind its own branches.
layout(set = 0, binding = 5) uniform usamplerBuffer scene_nodes_t;  // two texels per GpuNode
layout(std430, set = 0, binding = 6) readonly buffer SceneWords { uint scene_words[]; };
layout(set = 0, binding = 7) uniform usamplerBuffer scene_traced_t; // one texel per vertex

// Node i (a step that uses only its index and count fetches one texel: the other is dead code).
BvhNode scene_node(uint i) {
  uvec4 a = texelFetch(scene_nodes_t, int(2u * i));
  uvec4 b = texelFetch(scene_nodes_t, int(2u * i + 1u));
  BvhNode n;
  n.bounds_min = uintBitsToFloat(a.xyz);
  n.bounds_max = uintBitsToFloat(uvec3(a.w, b.xy));
  n.index = b.z;
  n.count = b.w;
  return n;
}

// The groundwork's name for the instance count (kernels written against it keep working).
#define instance_count scene_header.instance_count

vec3 scene_position(uint i) { return vec3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]); }

// False in a kernel that never sees a grid (trace_rays.comp over a BVH scene), or a top level
// (a scene without dynamic instances): llvmpipe runs both sides of every branch under a mask, so
// code that cannot be taken still costs each step.
#ifndef TRACE_GRID_CODE
#define TRACE_GRID_CODE true
#endif
#ifndef TRACE_TOP_CODE
#define TRACE_TOP_CODE true
#endif
// The header's fields the walk reads at every step, read once per walk (trace_begin, trace_resume):
// llvmpipe loads buffer data lane by lane even where every lane reads the same word, and does
// not hoist such a load out of the walk's loops.
struct TraceHeader {
  uint static_kind;
  uint static_node_base;
  uint static_index_base;
  uint cell_start_base;
  uint top_node_base;
  uint top_index_base;
  uint top_count;
  float box_far_scale;
  uvec3 grid_resolution;
};
TraceHeader th;

void trace_load_header() {
  th.static_kind = scene_header.static_kind;
  th.static_node_base = scene_header.static_node_base;
  th.static_index_base = scene_header.static_index_base;
  th.cell_start_base = scene_header.cell_start_base;
  th.top_node_base = scene_header.top_node_base;
  th.top_index_base = scene_header.top_index_base;
  th.top_count = scene_header.top_count;
  th.box_far_scale = scene_header.box_far_scale;
  if (TRACE_GRID_CODE) th.grid_resolution = scene_header.grid.resolution;
}

bool trace_static_grid() { return TRACE_GRID_CODE && th.static_kind == kStaticGrid; }

const float kTraceInf = 1.0 / 0.0;
const uint kStaticHit = 0xFFFFFFFEu;
const uint kPhaseStart = 0u;
const uint kPhaseStatic = 1u;
const uint kPhaseTop = 2u;
const uint kPhaseDone = 3u;

// ---- The conservative slab test (accel::intersect_box) -------------------------------------------

void trace_slab(float lo, float hi, float o, float inv, uint neg, inout float t0, inout float t1) {
  float tn = (lo - o) * inv;
  float tf = (hi - o) * inv;
  if (neg != 0u) {
    float s = tn;
    tn = tf;
    tf = s;
  }
  float tf_scaled = tf * th.box_far_scale;
  // NaN (0 · inf: origin on a slab plane of a parallel ray) keeps the current bound.
  t0 = tn > t0 ? tn : t0;
  t1 = tf_scaled < t1 ? tf_scaled : t1;
}

bool intersect_box(PreparedRay r, vec3 lo, vec3 hi, out float t_enter) {
  float t0 = r.tnear, t1 = r.tfar;
  trace_slab(lo.x, hi.x, r.org.x, r.inv_dir.x, r.neg.x, t0, t1);
  trace_slab(lo.y, hi.y, r.org.y, r.inv_dir.y, r.neg.y, t0, t1);
  trace_slab(lo.z, hi.z, r.org.z, r.inv_dir.z, r.neg.z, t0, t1);
  t_enter = t0;
  return t0 <= t1;
}

// Vertex k of traced triangle `tri` (binding 7 holds the positions themselves: no index to read
// before them).
vec3 traced_vertex(uint tri, uint k) {
  return uintBitsToFloat(texelFetch(scene_traced_t, int(3u * tri + k)).xyz);
}

bool trace_triangle(PreparedRay r, uint tri, out float t, out float u, out float v) {
#ifdef TRACE_ON_TRIANGLE
  TRACE_ON_TRIANGLE(); // trace_rays.comp counts the tests
#endif
  return intersect_watertight(r, traced_vertex(tri, 0u), traced_vertex(tri, 1u),
                              traced_vertex(tri, 2u), r.tfar, t, u, v);
}

// ---- Instances (NativeTracer's to_object) --------------------------------------------------------

// glm's mat4 · vec4 is (c0·x + c1·y) + (c2·z + c3·w), and mat3 · vec3 (c0·x + c1·y) + c2·z.
PreparedRay to_object(PreparedRay world, GpuTopEntry e) {
  vec3 org = (e.c0 * world.org.x + e.c1 * world.org.y) + (e.c2 * world.org.z + e.c3);
  vec3 dir = (e.c0 * world.dir.x + e.c1 * world.dir.y) + e.c2 * world.dir.z;
  return prepare_ray(org, dir, world.tnear, world.tfar);
}

// ---- Traversal state (per invocation) ------------------------------------------------------------

GpuTraceState tr;                    // where the walk stands (saved between dispatches)
uvec2 tr_stack[kTraceStackSize];     // (node, t_enter bits); entries >= tr.floor: the instance's
PreparedRay tr_world;                // the ray; its tfar shrinks with each closer hit
PreparedRay tr_local;                // in the current instance's object space
bool tr_any;                         // any hit ends the walk
bool tr_occluded;
// The grid's DDA constants, recomputed from the ray at every (re)start (UniformGrid::traverse).
double tr_t0;
vec3 tr_q, tr_scale;
ivec3 tr_dstep, tr_out;
uint tr_max_cells;

// The walk stands in `cell` (its triangles next), the next planes at distances s_next.
void trace_enter_cell(ivec3 cell, vec3 s_next) {
  tr.cell_x = cell.x;
  tr.cell_y = cell.y;
  tr.cell_z = cell.z;
  tr.s_next_x = s_next.x;
  tr.s_next_y = s_next.y;
  tr.s_next_z = s_next.z;
  uvec3 res = th.grid_resolution;
  uint c = uint(cell.x) + res.x * (uint(cell.y) + res.y * uint(cell.z));
#ifdef TRACE_ON_CELL
  TRACE_ON_CELL(c); // probe_grid_cells.comp records the walk
#endif
  tr.leaf_cursor = scene_words[th.cell_start_base + c];
  tr.leaf_end = scene_words[th.cell_start_base + c + 1u];
}

// Clip to the grid in double and set up the DDA (Amanatides & Woo) in grid units from the entry
// point, as UniformGrid::traverse does. `fresh`: also the walk's starting cell; false when the
// saved state resumes (the constants do not depend on tfar).
bool trace_grid_setup(bool fresh) {
  GridHeader g = scene_header.grid;
  double t0 = double(tr_world.tnear);
  double t1 = double(tr_world.tfar);
  for (int a = 0; a < 3; ++a) {
    double o = double(tr_world.org[a]);
    double lo = double(g.bounds_min[a]);
    double hi = double(g.bounds_max[a]);
    if (tr_world.dir[a] == 0.0) {
      if (o < lo || o > hi) return false;
      continue;
    }
    double inv = 1.0lf / double(tr_world.dir[a]);
    double tn = (lo - o) * inv;
    double tf = (hi - o) * inv;
    if (tn > tf) {
      double s = tn;
      tn = tf;
      tf = s;
    }
    t0 = t0 < tn ? tn : t0;
    t1 = tf < t1 ? tf : t1;
  }
  if (fresh && !(t0 <= t1)) return false;
  tr_t0 = t0;
  ivec3 cell;
  vec3 s_next;
  for (int a = 0; a < 3; ++a) {
    double p = double(tr_world.org[a]) + t0 * double(tr_world.dir[a]);
    double qa = (p - double(g.bounds_min[a])) / double(g.cell_size);
    int last = int(g.resolution[a]) - 1;
    double fq = floor(qa);
    cell[a] = int(fq < 0.0lf ? 0.0lf : (double(last) < fq ? double(last) : fq));
    tr_q[a] = float(qa);
    double scale = double(g.cell_size) / double(tr_world.dir[a]);
    float scale_f = tr_world.dir[a] == 0.0 ? kTraceInf : float(scale);
    tr_scale[a] = scale_f;
    if (tr_world.dir[a] > 0.0 && trace_finite(scale_f)) {
      tr_dstep[a] = 1;
      tr_out[a] = last + 1;
      float s = (float(cell[a] + 1) - tr_q[a]) * scale_f;
      s_next[a] = s;
    } else if (tr_world.dir[a] < 0.0 && trace_finite(scale_f)) {
      tr_dstep[a] = -1;
      tr_out[a] = -1;
      float s = (float(cell[a]) - tr_q[a]) * scale_f;
      s_next[a] = s;
    } else {
      tr_dstep[a] = 0;
      tr_out[a] = -2;
      s_next[a] = kTraceInf;
    }
  }
  tr_max_cells = g.resolution.x + g.resolution.y + g.resolution.z + 3u;
  if (fresh) {
    tr.cells = 0u;
    trace_enter_cell(cell, s_next);
  }
  return true;
}

void trace_start_top() {
  tr.phase = kPhaseDone;
  if (!TRACE_TOP_CODE || th.top_count == 0u) return;
  BvhNode root = scene_node(th.top_node_base);
  float t_enter;
  if (!intersect_box(tr_world, root.bounds_min, root.bounds_max, t_enter)) return;
  tr.phase = kPhaseTop;
  tr.node = th.top_node_base;
  tr.leaf_cursor = tr.leaf_end = 0u;
  tr.entry = kNoIndex;
  tr.floor = 0u;
  tr.sp = 0u;
}

void trace_start_static() {
  tr.phase = kPhaseStatic;
  tr.node = kNoIndex;
  tr.leaf_cursor = tr.leaf_end = 0u;
  tr.sp = 0u;
  if (th.static_kind == kStaticBvh) {
    BvhNode root = scene_node(th.static_node_base);
    float t_enter;
    if (intersect_box(tr_world, root.bounds_min, root.bounds_max, t_enter)) {
      tr.node = th.static_node_base;
      return;
    }
  } else if (trace_static_grid()) {
    if (trace_grid_setup(true)) return;
  }
  trace_start_top();
}

// A closer hit (or, for any-hit queries, the end of the walk).
void trace_record(uint instance, uint tri, uint prim, float t, float u, float v) {
  if (tr_any) {
    tr_occluded = true;
    tr.phase = kPhaseDone;
    return;
  }
  tr.hit_t = t;
  tr.hit_u = u;
  tr.hit_v = v;
  tr.hit_instance = instance;
  tr.hit_tri = tri;
  tr.hit_prim = prim;
  tr_world.tfar = t;
  tr_local.tfar = t;
}

// Leaves the current instance's BVH: the top level's walk goes on.
void trace_leave_instance() { tr.entry = kNoIndex; }

// Enters top-level box `box`: its BVH is walked with the ray in its object space.
void trace_enter_instance(uint box) {
  GpuTopEntry e = scene_top[box];
  tr_local = e.identity != 0u ? tr_world : to_object(tr_world, e);
  if (!ray_valid(tr_local)) return;
  BvhNode root = scene_node(e.node_base);
  float t_enter;
  if (!intersect_box(tr_local, root.bounds_min, root.bounds_max, t_enter)) return;
  tr.entry = box;
  tr.floor = tr.sp;
  tr.node = e.node_base;
}

// One step of a BVH walk (Bvh::traverse) inside a leaf: its next entry (a triangle, or an
// instance of the top level). Only while tr.leaf_cursor < tr.leaf_end.
void trace_bvh_leaf_step() {
  bool in_instance = false;
  if (TRACE_TOP_CODE) in_instance = tr.entry != kNoIndex;
  uint index_base;
  if (tr.phase == kPhaseStatic)
    index_base = th.static_index_base;
  else if (in_instance)
    index_base = scene_top[tr.entry].index_base;
  else
    index_base = th.top_index_base;
  PreparedRay r = in_instance ? tr_local : tr_world;
  uint prim = scene_words[index_base + tr.leaf_cursor];
  ++tr.leaf_cursor;
  if (TRACE_TOP_CODE && tr.phase == kPhaseTop && !in_instance) {
    trace_enter_instance(prim);
    return;
  }
  uint tri = tr.phase == kPhaseStatic ? prim : scene_top[tr.entry].tri_base + prim;
  float t, u, v;
  if (trace_triangle(r, tri, t, u, v)) {
    if (tr.phase == kPhaseStatic)
      trace_record(kStaticHit, tri, prim, t, u, v);
    else
      trace_record(scene_top[tr.entry].slot, tri, prim, t, u, v);
  }
}

// Node i0's two children (the BvhNode pair at index, index + 1) against the ray, as
// Bvh::traverse takes them: the nearer is the next node (kNoIndex when the ray misses both), the
// farther pushed with its entry distance.
void trace_children(PreparedRay r, uint i0, out uint node, inout uint sp) {
  BvhNode c0 = scene_node(i0);
  BvhNode c1 = scene_node(i0 + 1u);
  float e0, e1;
  bool hit0 = intersect_box(r, c0.bounds_min, c0.bounds_max, e0);
  bool hit1 = intersect_box(r, c1.bounds_min, c1.bounds_max, e1);
  node = kNoIndex;
  if (hit0 && hit1) {
    bool second = e1 < e0;
    tr_stack[sp++] = second ? uvec2(i0, floatBitsToUint(e0)) : uvec2(i0 + 1u, floatBitsToUint(e1));
    node = second ? i0 + 1u : i0;
  } else if (hit0 || hit1) {
    node = hit0 ? i0 : i0 + 1u;
  }
}

// One step of a BVH walk between leaves: a node, or a pop. Only while tr.leaf_cursor >=
// tr.leaf_end.
void trace_bvh_node_step() {
  bool in_instance = false;
  if (TRACE_TOP_CODE) in_instance = tr.entry != kNoIndex;
  uint node_base;
  if (tr.phase == kPhaseStatic)
    node_base = th.static_node_base;
  else if (in_instance)
    node_base = scene_top[tr.entry].node_base;
  else
    node_base = th.top_node_base;
  PreparedRay r = in_instance ? tr_local : tr_world;

  // Pop the nearest pending subtree the ray can still reach (its tfar may have shrunk), and
  // visit it in the same step: fewer loop iterations, each running every branch a SIMD vector's
  // rays need anyway.
  if (tr.node == kNoIndex) {
    if (in_instance && tr.sp == tr.floor) {
      trace_leave_instance();
      return;
    }
    if (tr.sp == 0u) {
      if (tr.phase == kPhaseStatic)
        trace_start_top();
      else
        tr.phase = kPhaseDone;
      return;
    }
    uvec2 e = tr_stack[--tr.sp];
    if (!(uintBitsToFloat(e.y) <= r.tfar)) return;
    tr.node = e.x;
  }

  BvhNode n = scene_node(tr.node);
  tr.node = kNoIndex;
  if (n.count == 0u) {
    trace_children(r, node_base + n.index, tr.node, tr.sp);
  } else {
    tr.leaf_cursor = n.index;
    tr.leaf_end = n.index + n.count;
  }
}

// One step of the grid's walk: a triangle of the current cell, or the move to the next cell.
void trace_grid_step() {
  if (tr.leaf_cursor < tr.leaf_end) {
    uint prim = scene_words[th.static_index_base + tr.leaf_cursor];
    ++tr.leaf_cursor;
    float t, u, v;
    if (trace_triangle(tr_world, prim, t, u, v)) trace_record(kStaticHit, prim, prim, t, u, v);
    return;
  }
  // The walk stops once the closest hit so far lies within the cells visited.
  double s_tfar_d = double(tr_world.tfar) - tr_t0;
  float s_tfar = float(s_tfar_d);
  vec3 s_next = vec3(tr.s_next_x, tr.s_next_y, tr.s_next_z);
  int axis = s_next.x < s_next.y ? (s_next.x < s_next.z ? 0 : 2) : (s_next.y < s_next.z ? 1 : 2);
  ivec3 cell = ivec3(tr.cell_x, tr.cell_y, tr.cell_z);
  if (s_tfar <= s_next[axis]) {
    trace_start_top();
    return;
  }
  cell[axis] += tr_dstep[axis];
  if (cell[axis] == tr_out[axis] || ++tr.cells >= tr_max_cells) {
    trace_start_top();
    return;
  }
  float s = (float(cell[axis] + (tr_dstep[axis] > 0 ? 1 : 0)) - tr_q[axis]) *
                    tr_scale[axis];
  s_next[axis] = s;
  trace_enter_cell(cell, s_next);
}

// Starts a walk over (tnear, tfar).
void trace_begin(vec3 org, vec3 dir, float tnear, float tfar, bool any_hit) {
  trace_load_header();
  tr_any = any_hit;
  tr_occluded = false;
  tr_world = prepare_ray(org, dir, tnear, tfar);
  tr_local = tr_world;
  tr.phase = ray_valid(tr_world) ? kPhaseStart : kPhaseDone;
  tr.node = kNoIndex;
  tr.leaf_cursor = tr.leaf_end = 0u;
  tr.entry = kNoIndex;
  tr.floor = tr.sp = tr.cells = 0u;
  tr.hit_t = kTraceInf;
  tr.hit_u = tr.hit_v = 0.0;
  tr.hit_instance = kNoIndex;
  tr.hit_tri = tr.hit_prim = 0u;
}

// Runs the walk until it ends (kRayDone) or `budget` steps are used up (kRayBudget). Falling out
// of the loop any other way means the driver cut it off (lavapipe's silent iteration cap):
// kRayPending then, and the caller must leave the ray's status unset.
//
// A BVH walk's steps run grouped, in two inner loops: the nodes and pops up to the next leaf, then
// that leaf's entries. Each ray takes exactly the steps of one flat loop, in the same order, but
// llvmpipe runs every branch of a loop's body for all 8 rays of its SIMD vector, so a loop that
// held both kinds of step paid for a node visit and a triangle test at every step.
// Lavapipe's iteration cap counts the inner loops' iterations and the outer loop's (one per leaf
// at most, so at most 1.5 per step).
bool trace_bvh_walk() {
  return tr.phase == kPhaseTop || (tr.phase == kPhaseStatic && !trace_static_grid());
}

// trace_run for a scene whose static set is a BVH and that has no top level, in a kernel with
// the grid's and the top level's code compiled out: the same steps in the same order, counted
// the same, with the walk's state in locals and without the phases' bookkeeping (llvmpipe pays
// for every instruction of a loop body at every step, taken or not).
uint trace_run_static_bvh(inout uint budget) {
  if (tr.phase == kPhaseDone) return kRayDone;
  if (budget == 0u) return kRayBudget;
  if (tr.phase == kPhaseStart) {
    --budget;
    trace_start_static(); // the root's box: kPhaseStatic, or kPhaseDone (no top level)
  }
  bool done = tr.phase == kPhaseDone;
  uint node = tr.node, cursor = tr.leaf_cursor, end = tr.leaf_end, sp = tr.sp;
  uint node_base = th.static_node_base, index_base = th.static_index_base;
  PreparedRay r = tr_world;
  for (;;) {
    if (done || budget == 0u) {
      tr.node = node;
      tr.leaf_cursor = cursor;
      tr.leaf_end = end;
      tr.sp = sp;
      tr_world.tfar = r.tfar;
      if (done) tr.phase = kPhaseDone;
      return done ? kRayDone : kRayBudget;
    }
    // Nodes and pops up to the next leaf (trace_bvh_node_step).
    while (budget != 0u && cursor >= end && !done) {
      --budget;
      if (node == kNoIndex) {
        if (sp == 0u) {
          done = true; // trace_start_top: no top level
          continue;
        }
        uvec2 e = tr_stack[--sp];
        if (!(uintBitsToFloat(e.y) <= r.tfar)) continue;
        node = e.x;
      }
      BvhNode n = scene_node(node);
      node = kNoIndex;
      if (n.count == 0u) {
        trace_children(r, node_base + n.index, node, sp);
      } else {
        cursor = n.index;
        end = n.index + n.count;
      }
    }
    // That leaf's triangles (trace_bvh_leaf_step).
    while (budget != 0u && cursor < end && !done) {
      --budget;
      uint prim = scene_words[index_base + cursor];
      ++cursor;
      float t, u, v;
      // trace_record's work, on the walk's locals: calling it (it also writes tr_local.tfar and
      // tr.phase, masked, at every test) cost 2-3% of device time on lavapipe.
      if (trace_triangle(r, prim, t, u, v)) {
        if (tr_any) {
          tr_occluded = true;
          done = true;
        } else {
          tr.hit_t = t;
          tr.hit_u = u;
          tr.hit_v = v;
          tr.hit_instance = kStaticHit;
          tr.hit_tri = prim;
          tr.hit_prim = prim;
          r.tfar = t;
        }
      }
    }
  }
  return kRayPending; // the driver cut the loop off
}

uint trace_run(inout uint budget) {
  if (!TRACE_GRID_CODE && !TRACE_TOP_CODE) return trace_run_static_bvh(budget);
  for (;;) {
    if (tr.phase == kPhaseDone) return kRayDone;
    if (budget == 0u) return kRayBudget;
    if (tr.phase == kPhaseStart) {
      --budget;
      trace_start_static();
    } else if (tr.phase == kPhaseStatic && trace_static_grid()) {
      --budget;
      trace_grid_step();
    } else {
      while (budget != 0u && tr.leaf_cursor >= tr.leaf_end && trace_bvh_walk()) {
        --budget;
        trace_bvh_node_step();
      }
      while (budget != 0u && tr.leaf_cursor < tr.leaf_end && trace_bvh_walk()) {
        --budget;
        trace_bvh_leaf_step();
      }
    }
  }
  return kRayPending;
}

// The unnormalised geometric normal (e1 × e2) as the CPU backends compute it.
void trace_set_normal(inout GpuHit hit, vec3 p0, vec3 p1, vec3 p2) {
  vec3 e1 = p1 - p0;
  vec3 e2 = p2 - p0;
  float nx = e1.y * e2.z - e2.y * e1.z;
  float ny = e1.z * e2.x - e2.z * e1.x;
  float nz = e1.x * e2.y - e2.x * e1.y;
  hit.ng_x = nx;
  hit.ng_y = ny;
  hit.ng_z = nz;
}

// The hit as the CPU backends report it (NativeTracer::resolve_static for the static set).
GpuHit trace_result() {
  GpuHit hit;
  hit.t = kTraceInf;
  hit.u = 0.0;
  hit.v = 0.0;
  hit.instance = kNoIndex;
  hit.primitive = 0u;
  hit.ng_x = hit.ng_y = hit.ng_z = 0.0;
  if (tr.hit_instance == kNoIndex) return hit;
  hit.t = tr.hit_t;
  hit.u = tr.hit_u;
  hit.v = tr.hit_v;
  hit.instance = tr.hit_instance;
  hit.primitive = tr.hit_prim;
  if (tr.hit_instance == kStaticHit) {
    // upper_bound over the static instances' first triangles (at most 32 halvings).
    uint base = scene_header.static_first_base;
    uint lo = 0u, n = scene_header.static_instances;
    while (n > 0u) {
      uint half_n = n / 2u;
      if (scene_words[base + lo + half_n] <= tr.hit_prim) {
        lo += half_n + 1u;
        n -= half_n + 1u;
      } else {
        n = half_n;
      }
    }
    uint k = lo - 1u;
    hit.instance = scene_words[scene_header.static_slot_base + k];
    hit.primitive = tr.hit_prim - scene_words[base + k];
  }
  trace_set_normal(hit, traced_vertex(tr.hit_tri, 0u), traced_vertex(tr.hit_tri, 1u),
                   traced_vertex(tr.hit_tri, 2u));
  return hit;
}

// ---- Saving and resuming (trace_rays.comp) -------------------------------------------------------

// After trace_begin's fields were reloaded into `tr` and the stack: the rays and the DDA's
// constants again.
void trace_resume(vec3 org, vec3 dir, float tnear, bool any_hit) {
  trace_load_header();
  tr_any = any_hit;
  tr_occluded = false;
  tr_world = prepare_ray(org, dir, tnear, tr.tfar);
  tr_local = tr_world;
  if (tr.phase == kPhaseStatic && trace_static_grid()) trace_grid_setup(false);
  if (TRACE_TOP_CODE && tr.entry != kNoIndex) {
    GpuTopEntry e = scene_top[tr.entry];
    if (e.identity == 0u) tr_local = to_object(tr_world, e);
  }
}

// ---- The contract ----------------------------------------------------------------------------------

uint trace_closest(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget, inout GpuHit hit) {
  trace_begin(org, dir, tnear, tfar, false);
  uint status = trace_run(budget);
  hit = trace_result();
  return status;
}

// Continues a trace_closest that returned kRayBudget (see the top of this file).
uint trace_closest_resume(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget,
                          inout GpuHit hit) {
  GpuHit best = hit;
  trace_begin(org, dir, tnear, best.instance != kNoIndex ? best.t : tfar, false);
  uint status = trace_run(budget);
  hit = trace_result();
  if (hit.instance == kNoIndex) hit = best;
  return status;
}

// occluded is set to true when anything lies within (tnear, tfar).
uint trace_any(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget, out bool occluded) {
  trace_begin(org, dir, tnear, tfar, true);
  uint status = trace_run(budget);
  occluded = tr_occluded;
  return status;
}

#endif
