#pragma once
/// \file
/// `specula compare A B`: how far image B is from reference A, as RMSE, PSNR and mean LDR-FLIP
/// (engine/image/metrics.h, engine/image/flip.h).

#include <iosfwd>
#include <string>

namespace specula::cli {

struct CompareOptions {
  std::string a;       ///< reference image (.png or .exr)
  std::string b;       ///< test image (.png or .exr)
  std::string heatmap; ///< PNG path for the FLIP error map coloured by magma; empty: none
  bool json = false;   ///< print {"rmse": …, "psnr_db": …, "flip_mean": …} instead of text
};

/// Reads both images by extension (PNG as sRGB → linear, EXR as linear floats), then prints
///   RMSE <linear RMSE>
///   PSNR <dB> dB          ("inf" for identical images)
///   FLIP <mean LDR-FLIP>  (default viewing condition, 67 pixels per degree)
/// or, with json, one object whose psnr_db is null for identical images (JSON has no infinity).
/// Writes the heatmap when asked. Returns 0. Throws specula::Error naming the file for unreadable
/// images, and naming both files and both sizes when the sizes differ.
int run_compare(const CompareOptions& options, std::ostream& out);

} // namespace specula::cli
