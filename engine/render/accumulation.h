#pragma once
/// \file
/// Progressive accumulation for the stochastic modes (path, shadow): while nothing changes, each
/// frame continues every pixel's low-discrepancy sequence (trace/sampler.h) where the previous
/// frame stopped, and the image shown is the mean of all the samples so far — so a still view
/// converges like one render with the sum of the frames' samples. Anything that changes the
/// image (the scene layer's delta, the camera, the settings, the image size) starts again from
/// the settings' own sample offset.

#include "specula/core/math.h"
#include "specula/image/framebuffer.h"
#include "specula/scene/components/camera.h"
#include "specula/trace/render_frame.h"

#include <cstdint>
#include <optional>
#include <vector>

namespace specula {

/// Whether `mode` draws random samples (path, shadow) and so accumulates.
[[nodiscard]] constexpr bool stochastic_mode(TraceMode mode) {
  return mode == TraceMode::Path || mode == TraceMode::Shadow;
}

/// Samples per pixel one frame of `settings` draws from each pixel's sequence: spp (path),
/// shadow_samples (shadow), 1 otherwise.
[[nodiscard]] std::uint32_t samples_per_frame(const TraceSettings& settings);

/// Whether two settings render the same image from the same sample positions: every field but
/// tile_size and threads, which never change the image (render_frame is deterministic across
/// them). A field added to TraceSettings must be added here too.
[[nodiscard]] bool same_image_settings(const TraceSettings& a, const TraceSettings& b);

/// The running mean of a stochastic mode's frames and what decides when it starts again. It
/// owns no renderer: the caller renders each frame with the sample offset begin() returns, then
/// hands the frame to add(). Sums are kept in double, so the mean of N frames of k samples
/// matches one frame of N·k samples to float rounding.
class Accumulation {
public:
  /// What the coming frame is.
  struct Frame {
    std::uint32_t sample_offset = 0; ///< TraceSettings::sample_offset to render it with
    bool restarted = false;          ///< the running mean was cleared for it
  };

  /// Decides how the next frame is rendered. It restarts (clears the mean, offset back to
  /// settings.sample_offset) on the first frame, when `scene_changed` (the scene layer's delta
  /// of this tick was not empty), when the camera, the image size, `accumulate` or the settings
  /// (same_image_settings) differ from the previous frame's, and when the next frame's samples
  /// would run past the sequences' 2^32 positions. With `accumulate` off frames are not
  /// averaged, but the offset still advances from frame to frame (each frame shows new noise,
  /// so a consumer averaging them itself still converges) and restarts in the same cases.
  Frame begin(const TraceSettings& settings, const Camera& camera, std::uint32_t width,
              std::uint32_t height, bool scene_changed, bool accumulate);

  /// Folds a frame rendered with begin()'s offset into the running mean and writes the mean of
  /// every frame since the restart into `mean` (resized to match). With accumulate off, copies
  /// the frame (unless `mean` is `frame`). Throws specula::Error when the frame's size is not
  /// the one begin() was given.
  void add(const Framebuffer& frame, Framebuffer& mean);

  /// Samples per pixel in the mean (this frame's included): frames since the restart × samples
  /// per frame; with accumulate off, one frame's.
  [[nodiscard]] std::uint64_t samples() const;
  /// Frames in the mean since the last restart (1 with accumulate off).
  [[nodiscard]] std::uint64_t frames() const { return accumulate_ ? frames_ : 1; }
  /// Restarts so far (the first frame counts as one).
  [[nodiscard]] std::uint64_t restarts() const { return restarts_; }
  /// Forgets everything: the next frame restarts.
  void reset();

private:
  std::vector<dvec3> sum_;   ///< per pixel, the sum of the frames' means since the restart
  std::uint64_t frames_ = 0; ///< since the restart, the coming frame included
  std::uint32_t width_ = 0, height_ = 0;
  std::uint32_t per_frame_ = 1;
  std::uint32_t first_offset_ = 0;
  bool accumulate_ = true;
  std::optional<TraceSettings> settings_;
  std::optional<Camera> camera_;
  std::uint64_t restarts_ = 0;
};

} // namespace specula
