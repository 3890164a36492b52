#pragma once
/// \file
/// LDR-FLIP, the perceptual difference evaluator of Andersson, Nilsson, Akenine-Möller,
/// Oskarsson, Åström and Fairchild, "FLIP: A Difference Evaluator for Alternating Images",
/// Proc. ACM Comput. Graph. Interact. Tech. 3(2), HPG 2020 (doi:10.1145/3406183). It predicts,
/// per pixel, how visible the difference is to a viewer flipping between a reference and a test
/// image at a given viewing distance: 0 = invisible, 1 = as different as the paper's maximum
/// (the Hunt-adjusted HyAB distance between pure green and pure blue).
/// Written from the paper's description; see flip.cpp for each step and its section.

#include "specula/image/framebuffer.h"

#include <cstdint>
#include <filesystem>
#include <vector>

namespace specula {

/// The paper's default viewing condition: a 0.7 m wide, 3840-pixel monitor seen from 0.7 m
/// gives 0.7 · (3840 / 0.7) · π/180 ≈ 67.02 pixels per degree, rounded to 67 as the paper does.
inline constexpr double kFlipDefaultPixelsPerDegree = 67.0;

/// Pixels per degree of visual angle for a monitor `width_m` metres wide with `resolution_x`
/// pixels across, seen from `distance_m` metres (small-angle approximation, as in the paper).
[[nodiscard]] double flip_pixels_per_degree(double distance_m, double width_m, double resolution_x);

struct FlipOptions {
  /// Must be finite and in (0, 1000]; filter radii grow linearly with it.
  double pixels_per_degree = kFlipDefaultPixelsPerDegree;
  /// The map is computed in bands of this many rows (0: the whole image at once), so the
  /// working memory beyond the error map is a few planes of one band, not of the image. The
  /// result is bit-identical for every band height.
  std::uint32_t band_rows = 128;
};

/// The FLIP error map: one value in [0, 1] per pixel, row-major like Framebuffer, and its mean
/// (the pooled single number the paper reports).
struct FlipResult {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<float> error_map;
  double mean = 0.0;

  [[nodiscard]] float at(std::uint32_t x, std::uint32_t y) const {
    return error_map[std::size_t{y} * width + x];
  }
};

/// LDR-FLIP between a reference and a test framebuffer (linear RGB). Both are first put through
/// the display model the paper assumes for LDR images: values clamped to [0, 1] (NaN → 0), i.e.
/// what an 8-bit sRGB monitor would show, before quantization. Not symmetric in general (the
/// feature term compares detector magnitudes, and the colour term clamps after filtering), so
/// pass the ground truth as `reference`. Throws specula::Error when the sizes differ or the
/// pixels per degree are out of range.
[[nodiscard]] FlipResult flip(const Framebuffer& reference, const Framebuffer& test,
                              const FlipOptions& options = {});

/// Bytes flip() allocates for images of this size: the error map (4 per pixel) and a bound on its
/// band buffers. Throws specula::Error for bad options, as flip() does.
[[nodiscard]] std::uint64_t flip_working_bytes(std::uint32_t width, std::uint32_t height,
                                               const FlipOptions& options = {});

/// The 'magma' colour map (Smith and van der Walt, matplotlib, CC0), the one the FLIP paper
/// uses for its error maps: t in [0, 1] (clamped) → sRGB-encoded colour in [0, 1]. A piecewise
/// linear fit through 17 of the 256 published entries (every 16th and the last), off the full
/// table by about 0.01 at most between them; perceptually ordered (lightness rises with t).
[[nodiscard]] vec3 magma(float t);

/// Writes the error map as an 8-bit sRGB PNG coloured by magma(): black-purple for 0, pale
/// yellow for 1. Throws specula::Error naming the path when it does not end in .png (the
/// extension must say what the file holds) or cannot be written.
void write_flip_heatmap(const FlipResult& result, const std::filesystem::path& path);

} // namespace specula
