#include "compare_command.h"

#include "specula/core/error.h"
#include "specula/core/memory_budget.h"
#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/metrics.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <ostream>
#include <sstream>

namespace specula::cli {

namespace {

std::string size_text(std::uint32_t width, std::uint32_t height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

[[noreturn]] void sizes_differ(const CompareOptions& options, const std::string& a_size,
                               const std::string& b_size) {
  throw Error(options.b, "image size " + b_size + " differs from " + printable(options.a, 200) +
                             " (" + a_size + ")");
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

std::uint64_t compare_memory_bytes(const ImageHeader& a, const ImageHeader& b, bool heatmap) {
  const std::uint64_t pixels =
      std::max(std::uint64_t{a.width} * a.height, std::uint64_t{b.width} * b.height);
  const std::uint64_t framebuffer = pixels * sizeof(vec3);
  const std::uint64_t flip_bytes =
      flip_working_bytes(std::max(a.width, b.width), std::max(a.height, b.height));
  // The heatmap: magma RGB (3 bytes per pixel), then stb's filtered rows (3), its deflate output
  // (at most 9/8 of that, in a buffer grown by doubling) and the PNG it is copied into.
  const std::uint64_t heatmap_bytes = heatmap ? pixels * 14 : 0;
  const std::uint64_t peak =
      std::max({framebuffer + a.decode_bytes, 2 * framebuffer + b.decode_bytes,
                2 * framebuffer + flip_bytes, flip_bytes + heatmap_bytes});
  return peak + (std::uint64_t{64} << 20);
}

int run_compare(const CompareOptions& options, std::ostream& out) {
  if (!options.heatmap.empty()) (void)check_image_output_path(options.heatmap, {ImageFormat::Png});
  const MemoryBudget budget = memory_budget(options.memory_limit, "--memory-limit");
  // From the headers, before any pixel is decoded; a header that cannot be read is left to the
  // reader, which says what is wrong with the file.
  const std::optional<ImageHeader> header_a = read_image_header(options.a);
  const std::optional<ImageHeader> header_b = read_image_header(options.b);
  if (header_a && header_b) {
    if (header_a->width != header_b->width || header_a->height != header_b->height) {
      sizes_differ(options, size_text(header_a->width, header_a->height),
                   size_text(header_b->width, header_b->height));
    }
    check_memory(compare_memory_bytes(*header_a, *header_b, !options.heatmap.empty()), budget,
                 options.a,
                 "comparing it with " + printable(options.b, 200) + " (" +
                     size_text(header_a->width, header_a->height) + ")");
  }

  std::optional<Framebuffer> a = read_image(options.a);
  std::optional<Framebuffer> b = read_image(options.b);
  if (a->width() != b->width() || a->height() != b->height()) {
    sizes_differ(options, size_text(a->width(), a->height()), size_text(b->width(), b->height()));
  }

  const double error = rmse(*a, *b);
  const double psnr_db = psnr_from_rmse(error);
  const FlipResult flip_result = flip(*a, *b);
  a.reset(); // the heatmap's encoding needs room more than the images do now
  b.reset();
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
