#pragma once
/// \file
/// How ray-cache cubes are used (`specula render --cache ...`, docs/cli.md). Small and free of
/// the cache's own types, so the render job can carry it.

#include <cstdint>
#include <optional>
#include <string_view>

namespace specula::cache {

/// How a cached texel is accepted for a ray leaving the object (docs/design/ray-cache.md).
enum class LookupMode : std::uint8_t {
  Direction, ///< the paper's: the texel the direction addresses, whatever the shading point
  Tau,       ///< only if the cached hit, seen from the shading point, lies within τ of the ray
  March,     ///< ray-march the stored distances from the shading point, then the τ test
};

enum class CachePolicy : std::uint8_t {
  Off,  ///< no cubes
  On,   ///< every cube looked up in the chosen mode, always
  Auto, ///< per cube, keep caching only while it saves time within the error bound
};

struct CacheSettings {
  CachePolicy policy = CachePolicy::Off;
  LookupMode lookup = LookupMode::Direction; ///< On: the mode; Auto: where its ladder starts
  float tau_deg = 0.5f;                      ///< Tau and March acceptance angle
  std::uint32_t resolution = 0;   ///< face resolution for every cube (0: each entity's own)
  std::uint32_t fill_budget = 0;  ///< at most this many texels written per frame (0: no limit)
  bool prefill = false;           ///< trace every outdated texel from the cube centre each frame
  /// Before each frame, trace up to this many outdated texels from the cube centre, those nearest
  /// (in tiles) to the directions the frame before looked up first (0: off). Whitted frames only.
  std::uint32_t fill_ahead = 0;
  double max_error_db = 40.0;     ///< Auto: the PSNR against uncached tracing it must keep
  std::uint32_t verify_every = 32; ///< Auto: one accepted lookup in this many is traced to check
  /// Path mode: whether texels serve leaving rays (the per-surface probes; measured to reach a
  /// given error later than uncached path tracing, so off unless asked for).
  bool path_serve = false;
  /// Path mode: the (moving-average) sample weight a texel needs before it serves lookups.
  std::uint32_t path_samples = 4;
  /// Path mode: while a texel serves, about this many of its lookups a frame are traced anyway
  /// (for the probe alone: the pixels take the texel's mean), so it keeps fresh samples.
  std::uint32_t path_refresh = 2;
  /// Path mode: each cube also keeps a coarse probe of the light arriving at its object from
  /// every direction, which lights the object's own diffuse lobe (no sampled bounce for it).
  bool path_irradiance = true;
  friend bool operator==(const CacheSettings&, const CacheSettings&) = default;
};

[[nodiscard]] std::optional<LookupMode> parse_lookup_mode(std::string_view name);
[[nodiscard]] const char* lookup_mode_name(LookupMode mode);
[[nodiscard]] std::optional<CachePolicy> parse_cache_policy(std::string_view name);
[[nodiscard]] const char* cache_policy_name(CachePolicy policy);

} // namespace specula::cache
