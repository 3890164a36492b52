// Hybrid mode's primary hits (engine/gpu/raster_primary.h): a pixel's hit from the visibility
// buffer the raster pass wrote instead of a traversal. The camera ray is intersected with exactly
// the triangle rasterised, by the watertight test trace.glsl uses, in the same space (world for
// the static set, the instance's object space through its top-level box otherwise) and with the
// same vertices, so t, u, v and the normal are the bits a traversal ending on that triangle
// gives. A pixel nothing covers is a miss. Two kinds of pixel are left to a traversal: those on
// an instance boundary of the visibility buffer (a 4-neighbour shows another instance or none),
// where the raster's coverage rules and its depth ties (surfaces that meet, as the Cornell box's
// walls do along pixel centres) may choose another surface than the traversal would; and those
// whose ray misses the triangle rasterised.
#ifndef SPECULA_VISIBILITY_GLSL
#define SPECULA_VISIBILITY_GLSL

#include "include/frame_common.glsl"

layout(std430, set = 0, binding = 23) readonly buffer Visibility { uvec2 visibility[]; };
layout(std430, set = 0, binding = 24) readonly buffer SlotBoxes { uint slot_box[]; };

vec3 visibility_vertex(GpuMesh mesh, uint tri, uint k) {
  return scene_position(mesh.first_vertex + triangles[3u * (mesh.first_triangle + tri) + k]);
}

// Pixel p's primary hit along (origin, direction), or false (counted as retraced): trace it.
bool visibility_hit(uint p, vec3 origin, vec3 direction, out GpuHit hit) {
  hit.t = kTraceInf;
  hit.u = 0.0;
  hit.v = 0.0;
  hit.instance = kNoIndex;
  hit.primitive = 0u;
  hit.ng_x = hit.ng_y = hit.ng_z = 0.0;
  uvec2 id = visibility[p];
  uint x = p % params.width;
  uint y = p / params.width;
  if ((x > 0u && visibility[p - 1u].x != id.x) ||
      (x + 1u < params.width && visibility[p + 1u].x != id.x) ||
      (y > 0u && visibility[p - params.width].x != id.x) ||
      (y + 1u < params.height && visibility[p + params.width].x != id.x)) {
    atomicAdd(counters.retraced, 1u);
    return false;
  }
  if (id.x == kNoIndex) return true;
  GpuMesh mesh = meshes[instances[id.x].mesh];
  PreparedRay r = prepare_ray(origin, direction, 0.0, kTraceInf);
  uint box = slot_box[id.x];
  if (box != kNoIndex && scene_top[box].identity == 0u) r = to_object(r, scene_top[box]);
  vec3 p0 = visibility_vertex(mesh, id.y, 0u);
  vec3 p1 = visibility_vertex(mesh, id.y, 1u);
  vec3 p2 = visibility_vertex(mesh, id.y, 2u);
  float t, u, v;
  if (!ray_valid(r) || !intersect_watertight(r, p0, p1, p2, r.tfar, t, u, v)) {
    atomicAdd(counters.retraced, 1u);
    return false;
  }
  hit.t = t;
  hit.u = u;
  hit.v = v;
  hit.instance = id.x;
  hit.primitive = id.y;
  trace_set_normal(hit, p0, p1, p2);
  return true;
}

#endif
