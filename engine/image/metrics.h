#pragma once
/// \file
/// Pixel-wise error metrics between two framebuffers of the same size: RMSE and PSNR. The
/// perceptual metric (FLIP) is in image/flip.h. Every function throws specula::Error when the
/// sizes differ (callers comparing files check first, to name the files in the message).

#include "specula/image/framebuffer.h"

namespace specula {

/// Root-mean-square error over all 3·width·height linear RGB values:
/// sqrt(Σ (a − b)² / (3·N)). 0 exactly when the images are equal; a constant offset d on every
/// channel gives |d|. Accumulated in double, so the result does not depend on summation noise at
/// the sizes Specula renders. NaN in either image gives NaN.
[[nodiscard]] double rmse(const Framebuffer& a, const Framebuffer& b);

/// RMSE after display encoding: each value clamped to [0, 1] and put through the sRGB OETF, as an
/// 8-bit PNG would show it (before quantization). Closer to what a viewer sees than linear RMSE,
/// which weights bright regions more.
[[nodiscard]] double rmse_srgb(const Framebuffer& a, const Framebuffer& b);

/// Peak signal-to-noise ratio in dB for peak value 1.0: 20·log10(1 / rmse(a, b)), over linear
/// values. Returns +infinity for identical images (rmse = 0), so "higher is better" holds
/// without a special case; callers printing JSON must map it themselves.
[[nodiscard]] double psnr(const Framebuffer& a, const Framebuffer& b);

/// 20·log10(1 / rmse) for an RMSE already computed; +infinity for 0.
[[nodiscard]] double psnr_from_rmse(double rmse);

} // namespace specula
