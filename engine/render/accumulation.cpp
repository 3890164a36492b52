#include "specula/render/accumulation.h"

#include "specula/core/error.h"

#include <algorithm>
#include <string>

namespace specula {

std::uint32_t samples_per_frame(const TraceSettings& settings) {
  switch (settings.mode) {
  case TraceMode::Path:
    return settings.spp;
  case TraceMode::Shadow:
    return settings.shadow_samples;
  case TraceMode::Cast:
  case TraceMode::Whitted:
    break;
  }
  return 1;
}

bool same_image_settings(const TraceSettings& a, const TraceSettings& b) {
  return a.mode == b.mode && a.max_depth == b.max_depth && a.min_weight == b.min_weight &&
         a.background == b.background && a.shadows == b.shadows && a.spp == b.spp &&
         a.shadow_samples == b.shadow_samples && a.sampling == b.sampling && a.seed == b.seed &&
         a.sample_offset == b.sample_offset;
}

Accumulation::Frame Accumulation::begin(const TraceSettings& settings, const Camera& camera,
                                        std::uint32_t width, std::uint32_t height,
                                        bool scene_changed, bool accumulate) {
  const std::uint32_t per_frame = std::max(1u, samples_per_frame(settings));
  // The sample index is 32 bits: a sequence that would run past it starts again (after 2^32
  // samples per pixel, far beyond convergence, so only a bug or a test reaches it).
  const std::uint64_t next = std::uint64_t{settings.sample_offset} + frames_ * per_frame;
  const bool exhausted = next + per_frame > (std::uint64_t{1} << 32);
  const bool restart = !settings_ || scene_changed || exhausted || camera != *camera_ ||
                       width != width_ || height != height_ || accumulate != accumulate_ ||
                       !same_image_settings(settings, *settings_);
  if (restart) {
    frames_ = 0;
    ++restarts_;
    settings_ = settings;
    camera_ = camera;
    width_ = width;
    height_ = height;
    accumulate_ = accumulate;
    per_frame_ = per_frame;
    first_offset_ = settings.sample_offset;
    if (accumulate)
      sum_.assign(std::size_t{width} * height, dvec3(0.0));
    else
      sum_ = {}; // frames are shown as they are: no sum to keep
  }
  const Frame frame{static_cast<std::uint32_t>(first_offset_ + frames_ * per_frame_), restart};
  ++frames_;
  return frame;
}

void Accumulation::add(const Framebuffer& frame, Framebuffer& mean) {
  if (frames_ == 0) throw Error("accumulation", "add() without begin()");
  if (frame.width() != width_ || frame.height() != height_)
    throw Error("accumulation", "the frame is " + std::to_string(frame.width()) + "x" +
                                    std::to_string(frame.height()) + ", begin() was given " +
                                    std::to_string(width_) + "x" + std::to_string(height_));
  if (mean.width() != width_ || mean.height() != height_) mean = Framebuffer(width_, height_);
  if (!accumulate_) {
    if (&mean != &frame)
      std::copy(frame.pixels().begin(), frame.pixels().end(), mean.pixels().begin());
    return;
  }
  const std::span<const vec3> in = frame.pixels();
  const std::span<vec3> out = mean.pixels();
  const double inv = 1.0 / double(frames_);
  // One pass: the first frame's mean is the frame itself, bit for bit (x · 1.0 and the float
  // round trip are exact).
  for (std::size_t i = 0; i < in.size(); ++i) {
    sum_[i] += dvec3(in[i]);
    out[i] = vec3(sum_[i] * inv);
  }
}

std::uint64_t Accumulation::samples() const {
  return accumulate_ ? frames_ * per_frame_ : (frames_ > 0 ? per_frame_ : 0);
}

void Accumulation::reset() {
  settings_.reset();
  camera_.reset();
  sum_ = {};
  frames_ = 0;
}

} // namespace specula
