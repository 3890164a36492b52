// What every frame kernel shares: the scene (trace.glsl), the frame's tables and counters
// (shading.glsl), and the scene features, as specialisation constants so that a scene pays only
// for what it has (no refraction code without dielectrics, no shadow rays with shadows off, the
// light loop unrolled to the scene's light count).
#ifndef SPECULA_FRAME_COMMON_GLSL
#define SPECULA_FRAME_COMMON_GLSL

#include "shared/frame_layout.h"
// trace.glsl's grid walk and top level, as trace_rays.comp's ids 1 and 2 (llvmpipe pays for
// untaken branches in every traversal step): false for a BVH scene / a scene without dynamic
// instances. Ids after path.glsl's 7-10.
layout(constant_id = 11) const bool kGridCode = true;
layout(constant_id = 12) const bool kTopCode = true;
#define TRACE_GRID_CODE kGridCode
#define TRACE_TOP_CODE kTopCode
#include "include/trace.glsl"
#include "include/shading.glsl"

layout(constant_id = 0) const bool kWhitted = true;     // false: cast mode
layout(constant_id = 1) const bool kShadows = true;     // trace shadow rays
layout(constant_id = 2) const bool kDielectrics = true; // some material transmits
layout(constant_id = 3) const bool kSpecular = true;    // some material reflects or transmits
layout(constant_id = 4) const uint kLightCount = 0u;
// constant_id 5: kCache (frame_cache.glsl), the frame has ray-cache cubes; 7-10: path.glsl's.
layout(constant_id = 6) const bool kRasterPrimary = false; // hybrid mode (single kernel)
#include "include/frame_cache.glsl"
#include "include/trace_pool.glsl"

#endif
