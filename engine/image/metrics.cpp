#include "specula/image/metrics.h"

#include "specula/core/error.h"
#include "specula/image/srgb.h"

#include <cmath>
#include <limits>
#include <string>

namespace specula {

namespace {

void check_same_size(const Framebuffer& a, const Framebuffer& b, const char* metric) {
  if (a.width() != b.width() || a.height() != b.height()) {
    throw Error(std::string(metric) + ": image sizes differ (" + std::to_string(a.width()) + "x" +
                std::to_string(a.height()) + " vs " + std::to_string(b.width()) + "x" +
                std::to_string(b.height()) + ")");
  }
}

/// sqrt(mean squared difference) of encode(channel) over every channel of every pixel.
template <class Encode>
double root_mean_square(const Framebuffer& a, const Framebuffer& b, Encode encode) {
  const auto pa = a.pixels();
  const auto pb = b.pixels();
  double sum = 0.0;
  for (std::size_t i = 0; i < pa.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const double d =
          static_cast<double>(encode(pa[i][c])) - static_cast<double>(encode(pb[i][c]));
      sum += d * d;
    }
  }
  return std::sqrt(sum / (3.0 * static_cast<double>(pa.size())));
}

} // namespace

double rmse(const Framebuffer& a, const Framebuffer& b) {
  check_same_size(a, b, "rmse");
  return root_mean_square(a, b, [](float v) { return v; });
}

double rmse_srgb(const Framebuffer& a, const Framebuffer& b) {
  check_same_size(a, b, "rmse_srgb");
  return root_mean_square(a, b, [](float v) { return linear_to_srgb(v); });
}

double psnr_from_rmse(double rmse) {
  if (rmse == 0.0) return std::numeric_limits<double>::infinity();
  return 20.0 * std::log10(1.0 / rmse);
}

double psnr(const Framebuffer& a, const Framebuffer& b) {
  check_same_size(a, b, "psnr");
  return psnr_from_rmse(rmse(a, b));
}

} // namespace specula
