// Ray-cache cube addressing and texels on the device, bit for bit as engine/cache/cube_map.h
// (face by the major axis, ties to x then y; nearest texel) and ray_cache.cpp (half-float
// texels). Nothing is fused, as in the C++ build (common.glsl).
#ifndef SPECULA_CUBE_GLSL
#define SPECULA_CUBE_GLSL

// cube_coord: the face and (t_u, t_v) that direction s (not zero) addresses.
uint cube_coord(vec3 s, out float u, out float v) {
  float ax = abs(s.x), ay = abs(s.y), az = abs(s.z);
  float sc, tc, ma;
  uint face;
  if (ax >= ay && ax >= az) {
    ma = ax;
    face = s.x >= 0.0 ? 0u : 1u;
    sc = s.x >= 0.0 ? -s.z : s.z;
    tc = -s.y;
  } else if (ay >= az) {
    ma = ay;
    face = s.y >= 0.0 ? 2u : 3u;
    sc = s.x;
    tc = s.y >= 0.0 ? s.z : -s.z;
  } else {
    ma = az;
    face = s.z >= 0.0 ? 4u : 5u;
    sc = s.z >= 0.0 ? s.x : -s.x;
    tc = -s.y;
  }
  float pu = 0.5 * (sc / ma + 1.0);
  float pv = 0.5 * (tc / ma + 1.0);
  u = pu;
  v = pv;
  return face;
}

// texel_of: face·res² + row·res + column of the nearest texel.
uint cube_texel(vec3 s, uint resolution) {
  float u, v;
  uint face = cube_coord(s, u, v);
  float r = float(resolution);
  float ur = u * r, vr = v * r;
  uint x = min(resolution - 1u, uint(max(0.0, ur)));
  uint y = min(resolution - 1u, uint(max(0.0, vr)));
  return (face * resolution + y) * resolution + x;
}

// A cache::Texel as four words: rgb0 | rgb1 << 16, rgb2 | distance << 16, hit,
// seen | rays << 16 | state << 24 (the struct's little-endian bytes).
vec3 texel_radiance(uvec4 t) {
  return vec3(unpackHalf2x16(t.x).x, unpackHalf2x16(t.x).y, unpackHalf2x16(t.y).x);
}
float texel_distance(uvec4 t) { return unpackHalf2x16(t.y).y; }
uint texel_hit(uvec4 t) { return t.z; }
uint texel_seen(uvec4 t) { return t.w & 0xFFFFu; }
bool texel_valid(uvec4 t) { return ((t.w >> 24) & 1u) != 0u; }

#endif
