#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Ray-cache cubes (cache::RayCaches, when the render job caches): keeps one cube per cached
/// entity and outdates, through the visibility graph, the texels that what moved this frame may
/// have changed (cache/ray_cache.h); with --cache-prefill, traces every outdated texel from its
/// cube's centre; with --cache-fill-ahead K, up to K of them nearest the directions the last
/// frame looked up. Runs after the acceleration system (the tracer is current) and before render.
void cache_invalidation_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
