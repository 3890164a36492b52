#pragma once
/// \file
/// Dynamic resolution: the scale at which to render the next frame so that frames take about a
/// target time. The window front ends (the editor, the games) feed it the time of each frame they
/// show and render the next one at width·scale × height·scale; presentation scales the frame up
/// to the window. A frame's cost is modelled as proportional to its pixels (scale²), corrected
/// every frame by what was measured; the scale moves by at most 25% per frame, stays put within
/// ±5% of the target (no flicker between sizes), and is quantised to 1/64 so that sizes repeat.

#include <cstdint>
#include <utility>

namespace specula {

class ResolutionGovernor {
public:
  /// target_ms: the frame time to hold (0 or less: off, the scale stays 1). min_scale: the
  /// coarsest scale allowed, in (0, 1].
  explicit ResolutionGovernor(double target_ms, float min_scale = 0.25f);

  /// The scale for the next frame, given the last frame's time (ms) rendered at scale(). A
  /// non-finite or non-positive time is ignored (the scale stays).
  float next(double frame_ms);
  [[nodiscard]] float scale() const { return scale_; }
  [[nodiscard]] bool enabled() const { return target_ms_ > 0.0; }

  /// width·scale × height·scale, rounded, each side at least 1 and at most the full side.
  [[nodiscard]] static std::pair<std::uint32_t, std::uint32_t> scaled(std::uint32_t width,
                                                                      std::uint32_t height,
                                                                      float scale);

private:
  double target_ms_;
  float min_scale_;
  float scale_ = 1.0f;
};

} // namespace specula
