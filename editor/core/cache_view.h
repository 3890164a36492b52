#pragma once
/// \file
/// The editor's cache view: the ray-cache cubes' texels shown on the objects that own them. Each
/// pixel whose camera ray hits an object with a cube is tinted by what the frame's lookup of the
/// ray leaving that object there found in its texel (RayCacheStore::lookup_log, the first leaving
/// ray's): green valid and accepted, red outdated (traced, then written), yellow valid but refused
/// by the parallax test (tau, march), grey when auto has switched the cube off. Other pixels are
/// left as they are. So a move shows, in the next frame, as red where the invalidation outdated
/// the texels that frame's rays read.

#include <cstdint>

namespace specula {
class Framebuffer;
class SceneLayer;
class Tracer;
struct Camera;
namespace cache {
class RayCacheStore;
}
} // namespace specula

namespace specula::editor {

/// Pixels of cached objects by what their lookup found.
struct CacheViewCounts {
  std::uint64_t valid = 0, outdated = 0, rejected = 0, off = 0;
  friend bool operator==(const CacheViewCounts&, const CacheViewCounts&) = default;
};

/// Tints `image`, the frame just rendered from `camera` over `layer` (which `tracer` is up to date
/// with) with `store` as its hook, logging its lookups (set_log_lookups); returns how many pixels
/// got each tint.
CacheViewCounts tint_cache_view(Framebuffer& image, const Camera& camera, const SceneLayer& layer,
                                const Tracer& tracer, const cache::RayCacheStore& store);

} // namespace specula::editor
