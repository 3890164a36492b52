#include "compare_command.h"

#include "specula/core/error.h"
#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/metrics.h"

#include <cmath>
#include <ostream>
#include <sstream>

namespace specula::cli {

namespace {

std::string size_text(const Framebuffer& image) {
  return std::to_string(image.width()) + "x" + std::to_string(image.height());
}

/// 17 significant digits, enough to read back the same double; JSON null for non-finite values
/// (JSON has no infinity).
std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

} // namespace

int run_compare(const CompareOptions& options, std::ostream& out) {
  const Framebuffer a = read_image(options.a);
  const Framebuffer b = read_image(options.b);
  if (a.width() != b.width() || a.height() != b.height()) {
    throw Error(options.b, "image size " + size_text(b) + " differs from " + options.a + " (" +
                               size_text(a) + ")");
  }

  const double error = rmse(a, b);
  const double psnr_db = psnr_from_rmse(error);
  const FlipResult flip_result = flip(a, b);
  if (!options.heatmap.empty()) write_flip_heatmap(flip_result, options.heatmap);

  if (options.json) {
    out << "{\"rmse\": " << json_number(error) << ", \"psnr_db\": " << json_number(psnr_db)
        << ", \"flip_mean\": " << json_number(flip_result.mean) << "}\n";
  } else {
    out << "RMSE " << error << "\nPSNR " << psnr_db << " dB\nFLIP " << flip_result.mean << "\n";
  }
  return 0;
}

} // namespace specula::cli
