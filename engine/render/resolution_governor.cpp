#include "specula/render/resolution_governor.h"

#include <algorithm>
#include <cmath>

namespace specula {

namespace {
constexpr float kQuantum = 1.0f / 64.0f;
constexpr double kDeadBand = 0.05; ///< within ±5% of the target: keep the scale
constexpr double kMaxStep = 1.25;  ///< per frame, the scale changes by at most this factor
} // namespace

ResolutionGovernor::ResolutionGovernor(double target_ms, float min_scale)
    : target_ms_(std::isfinite(target_ms) ? target_ms : 0.0),
      min_scale_(std::isfinite(min_scale) ? std::clamp(min_scale, kQuantum, 1.0f) : 0.25f) {}

float ResolutionGovernor::next(double frame_ms) {
  if (!enabled() || !std::isfinite(frame_ms) || frame_ms <= 0.0) return scale_;
  const double ratio = target_ms_ / frame_ms;
  if (std::abs(ratio - 1.0) <= kDeadBand) return scale_;
  // Cost ∝ pixels ∝ scale²: the side scales by √ratio, limited per frame.
  const double step = std::clamp(std::sqrt(ratio), 1.0 / kMaxStep, kMaxStep);
  float wanted = float(double(scale_) * step);
  // Quantised down: a step up never overshoots the model's scale; a step down always moves.
  wanted = std::floor(wanted / kQuantum) * kQuantum;
  if (step < 1.0 && wanted >= scale_) wanted = scale_ - kQuantum;
  scale_ = std::clamp(wanted, min_scale_, 1.0f);
  return scale_;
}

std::pair<std::uint32_t, std::uint32_t> ResolutionGovernor::scaled(std::uint32_t width,
                                                                   std::uint32_t height,
                                                                   float scale) {
  const double s = std::isfinite(scale) ? std::clamp(double(scale), 0.0, 1.0) : 1.0;
  const auto side = [&](std::uint32_t full) {
    return std::clamp<std::uint32_t>(std::uint32_t(std::lround(double(full) * s)), 1u,
                                     std::max(full, 1u));
  };
  return {side(width), side(height)};
}

} // namespace specula
