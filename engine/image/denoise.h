#pragma once
/// \file
/// The edge-avoiding à-trous wavelet filter (Dammertz, Sewtz, Hanika, Lensch, "Edge-Avoiding
/// À-Trous Wavelet Transform for fast Global Illumination Filtering", HPG 2010) for path-traced
/// images: a 5×5 B3-spline kernel applied with growing holes (step 2^i), each tap weighted by how
/// close its colour, normal and position-in-depth are to the centre's. Guided by what the
/// integrator wrote at the primary hits (GuideBuffers).

#include "specula/core/math.h"
#include "specula/image/framebuffer.h"

#include <cstdint>
#include <span>
#include <vector>

namespace specula {

/// Per pixel, at the primary hit: the surface's albedo (what divides the lighting out of the
/// colour), its shading normal (unit; zero on a miss) and the hit distance (+inf on a miss).
struct GuideBuffers {
  std::vector<vec3> albedo;
  std::vector<vec3> normal;
  std::vector<float> depth;
  void resize(std::size_t n) {
    albedo.resize(n);
    normal.resize(n);
    depth.resize(n);
  }
  [[nodiscard]] std::size_t size() const { return depth.size(); }
};

/// The filter's knobs. Weights are exp(−d²/σ²) of the distance d between a tap and the centre, as
/// Dammertz et al.; the three factors multiply.
struct DenoiseSettings {
  /// Filter levels (at most 12), level i with taps 2^i pixels apart: the footprint is
  /// (4·(2^iterations − 1) + 1)² pixels.
  std::uint32_t iterations = 5;
  /// Colour weight scale, on the demodulated colour (colour ÷ albedo, i.e. the lighting), halved
  /// at every level as the paper: the coarse levels, whose taps are already smooth, only average
  /// what is alike. +inf turns the colour weight off.
  float sigma_color = 0.6f;
  float sigma_normal = 0.1f; ///< normal weight scale, on the distance between unit normals
  /// Depth weight scale, relative to the centre's depth: the tap's depth is compared with what the
  /// centre's depth gradient predicts at the tap's offset, so slanted planes are not cut apart.
  float sigma_depth = 0.1f;
  /// With a per-pixel variance (atrous_denoise's `variance`), the colour weight is
  /// exp(−|Δc|²/(σ_v²·Var)) instead (Schied et al., "Spatiotemporal Variance-Guided Filtering",
  /// HPG 2017, in the Gaussian form of the other weights): Var is the variance of the centre's
  /// estimate (demodulated luminance), 3×3-prefiltered before the first level and carried through
  /// the levels as the variance of each level's weighted mean. A noisy pixel (a firefly) then
  /// mixes with its neighbours while a converged one keeps its value, whatever the image's scale;
  /// sigma_color is not used. The variance shrinks level by level as the estimate is averaged, so
  /// σ_v is large: 12 gave the lowest FLIP at 8 and at 16 samples on the Cornell box among 1…32
  /// (docs/PERFORMANCE.md §8).
  float sigma_variance = 12.0f;
  std::uint32_t threads = 0; ///< 0: every hardware thread
  /// Pixels per vector step: 0 the widest this CPU runs (8 with AVX2, else 4), 4 (SSE2) or 8
  /// (AVX2; an error on a CPU without it). The result is the same bits for either.
  std::uint32_t lanes = 0;
};

/// The per-pixel variance of a running mean of frames, for the variance-guided colour weight:
/// each frame adds its pixels' demodulated luminance (the colour divided by that frame's albedo
/// guide, as the filter divides it), and the variance of the mean is the sample variance of the
/// frames' values over their count.
class LuminanceMoments {
public:
  /// Forgets every frame; the next add() starts a new mean over `pixels` pixels.
  void reset(std::size_t pixels);
  /// Folds one frame in (its guides, written with it). Non-finite values are left out of that
  /// pixel's sums. Throws specula::Error when the sizes are not reset()'s.
  void add(const Framebuffer& frame, const GuideBuffers& guides);
  [[nodiscard]] std::uint32_t frames() const { return frames_; }
  /// Per pixel, the variance of the mean of its frames' values; empty while fewer than two frames
  /// were added (a variance needs two), so the caller falls back to the fixed colour weight. A
  /// pixel with fewer than two finite values gets +inf (unknown: its colour weight is off).
  [[nodiscard]] std::vector<float> variance_of_mean() const;

private:
  std::vector<double> sum_, sum2_;
  std::vector<std::uint32_t> count_;
  std::uint32_t frames_ = 0;
};

/// Filters `noisy` into `out` (assigned noisy's size; `out` may be `noisy` itself). The colour
/// is divided by the albedo guide before filtering and multiplied back after (channels with an
/// albedo below 1/1000 are filtered as they are), so textures stay sharp and only the lighting is
/// smoothed. Guides must have noisy's pixel count. Pixels without a hit (depth +inf or NaN) or
/// with a non-finite colour or normal are copied through and never used as taps; taps outside the
/// image are left out. Every level reads only the previous one, so the result is the same whatever
/// the thread count. `variance`, when not empty, is each pixel's estimate variance
/// (LuminanceMoments::variance_of_mean) and selects the variance-guided colour weight; negative or
/// NaN entries are taken as +inf. Throws specula::Error on mismatched sizes or settings out of
/// range.
void atrous_denoise(const Framebuffer& noisy, const GuideBuffers& guides,
                    const DenoiseSettings& settings, Framebuffer& out,
                    std::span<const float> variance = {});

} // namespace specula
