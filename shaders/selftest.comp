#version 460
// The foundation's own test kernel (tests/gpu/test_vk_context.cpp): out[i] = in[i] * scale +
// offset (specialization constant 0: scale; push constant: offset), and a loop of `loop_count`
// iterations whose completed count is written, which shows the driver's silent loop cap.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"

layout(local_size_x = 64) in;
layout(constant_id = 0) const uint kScale = 1u;
layout(push_constant) uniform Push { uint offset; uint count; uint loop_count; } pc;
layout(std430, set = 0, binding = 0) readonly buffer In { uint data_in[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Out { uint data_out[]; };
layout(std430, set = 0, binding = 2) volatile buffer Loops { uint loops_done[]; };

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pc.count) return;
  data_out[i] = data_in[i] * kScale + pc.offset;
  loops_done[i] = 0u;
  for (uint k = 0u; k < pc.loop_count; ++k) loops_done[i] += 1u;
}
