#pragma once
/// \file
/// `specula compare A B`: how far image B is from reference A, as RMSE, PSNR and mean LDR-FLIP
/// (engine/image/metrics.h, engine/image/flip.h).

#include "specula/image/image_header.h"

#include <cstdint>
#include <iosfwd>
#include <string>

namespace specula::cli {

struct CompareOptions {
  std::string a;       ///< reference image (.png or .exr)
  std::string b;       ///< test image (.png or .exr)
  std::string heatmap; ///< PNG path for the FLIP error map coloured by magma; empty: none
  bool json = false;   ///< print {"rmse": …, "psnr_db": …, "flip_mean": …} instead of text
  /// A size such as "4G" (core/memory_budget.h); empty: default_memory_budget().
  std::string memory_limit = {};
};

/// A bound on the bytes run_compare allocates for two images of these headers (the larger
/// header's size stands for both) and a heatmap or not: at its peak, both framebuffers (12 bytes
/// per pixel each) and the second image's decoding, or both and FLIP's working memory, or FLIP's
/// map and the heatmap's encoding (the framebuffers are freed before it), plus 64 MiB for the
/// rest of the program.
[[nodiscard]] std::uint64_t compare_memory_bytes(const ImageHeader& a, const ImageHeader& b,
                                                 bool heatmap);

/// Reads both images by extension (PNG as sRGB → linear, EXR as linear floats), then prints
///   RMSE <linear RMSE>
///   PSNR <dB> dB          ("inf" for identical images)
///   FLIP <mean LDR-FLIP>  (default viewing condition, 67 pixels per degree)
/// or, with json, one object whose psnr_db is null for identical images (JSON has no infinity).
/// Writes the heatmap when asked. Returns 0. Before decoding anything, checks the heatmap path
/// (check_image_output_path, .png only) and, from the image headers, that the sizes agree and
/// that compare_memory_bytes fits the memory budget. Throws specula::Error naming the file for
/// unreadable images, naming both files and both sizes when the sizes differ, and naming the
/// first file with what the comparison needs and the budget when it does not fit.
int run_compare(const CompareOptions& options, std::ostream& out);

} // namespace specula::cli
