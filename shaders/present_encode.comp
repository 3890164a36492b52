#version 460
// A device frame presented where it is (engine/present/canvas.cpp): each canvas pixel takes the
// frame's linear radiance under it — letterboxed and scaled by the taps the host computed with
// the same functions as encode_srgb8_into (linear_source, or nearest_source as taps of weight 0)
// — and encodes it to 8-bit sRGB by the host encoder's thresholds (Srgb8Encoder), so that the
// bytes equal the CPU path's. The canvas then copies them into its image.
layout(local_size_x = 8, local_size_y = 8) in;

struct Tap {
  uint lo;
  uint hi;
  float weight;
  uint unused;
};

layout(std430, set = 0, binding = 0) readonly buffer Radiance { vec4 radiance[]; };
// The drawn rectangle's dw columns, then its dh rows.
layout(std430, set = 0, binding = 1) readonly buffer Taps { Tap taps[]; };
// threshold[k]: the least value that encodes to k (threshold[0] = 0, threshold[256] = 2).
layout(std430, set = 0, binding = 2) readonly buffer Thresholds { float threshold[257]; };
layout(std430, set = 0, binding = 3) writeonly buffer Pixels { uint pixels[]; };

layout(push_constant) uniform Push {
  uint width;     // the canvas
  uint height;
  uint ox;        // the drawn rectangle, centred (letterbox bars around it)
  uint oy;
  uint dw;
  uint dh;
  uint src_width; // the frame's row length
  uint bgra;      // 1: blue in the first byte (a swapchain's order)
} pc;

// Clamps to [0, 1] with NaN, -0 and negatives to 0 (specula::clamp_unit).
float clamp_unit(float v) { return v > 0.0 ? (v < 1.0 ? v : 1.0) : 0.0; }

// The largest k with threshold[k] <= v: eight halvings of [0, 256).
uint encode(float linear) {
  const float v = clamp_unit(linear);
  uint lo = 0u, hi = 256u;
  for (uint i = 0u; i < 8u; ++i) {
    const uint mid = (lo + hi) >> 1;
    if (threshold[mid] <= v)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

// specula::lerp_taps: a exactly at weight 0; no fused multiply-add, as on the host.
vec3 lerp_taps(vec3 a, vec3 b, float w) {
  vec3 r = (1.0 - w) * a + w * b;
  return w == 0.0 ? a : r;
}

vec3 at(uint x, uint y) { return radiance[y * pc.src_width + x].rgb; }

void main() {
  const uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
  if (x >= pc.width || y >= pc.height) return;
  uint packed = 0xff000000u; // black bar, alpha 255
  if (x >= pc.ox && x < pc.ox + pc.dw && y >= pc.oy && y < pc.oy + pc.dh) {
    const Tap tx = taps[x - pc.ox];
    const Tap ty = taps[pc.dw + (y - pc.oy)];
    const vec3 c = lerp_taps(lerp_taps(at(tx.lo, ty.lo), at(tx.hi, ty.lo), tx.weight),
                             lerp_taps(at(tx.lo, ty.hi), at(tx.hi, ty.hi), tx.weight), ty.weight);
    const uint r = encode(c.r), g = encode(c.g), b = encode(c.b);
    packed |= (pc.bgra != 0u ? (b | (r << 16)) : (r | (b << 16))) | (g << 8);
  }
  pixels[y * pc.width + x] = packed;
}
