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

struct DenoiseSettings {
  std::uint32_t iterations = 5; ///< filter levels: the footprint is (4·2^iterations + 1)²
  float sigma_color = 0.6f;     ///< colour weight scale (halved at every level, as the paper)
  float sigma_normal = 0.1f;    ///< normal weight scale
  float sigma_depth = 0.1f;     ///< relative depth weight scale
  std::uint32_t threads = 0;    ///< 0: every hardware thread
};

/// Filters `noisy` into `out` (resized to match). Guides must be noisy's size. Pixels without a
/// hit (depth +inf) are copied through. Throws specula::Error on mismatched sizes.
void atrous_denoise(const Framebuffer& noisy, const GuideBuffers& guides,
                    const DenoiseSettings& settings, Framebuffer& out);

} // namespace specula
