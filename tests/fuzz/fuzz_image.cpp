// Harness for the image readers (PNG through stb_image, EXR through the OpenEXR library):
// read_image, and its promises: a size within kMaxFramebufferSide, every value finite, and PNG
// values in [0, 1] (8 or 16-bit levels through the sRGB EOTF). SPECULA_FUZZ_FILE names the
// scratch file, and so the format: image.png or image.exr.

#include "fuzz_support.h"

#include "specula/image/framebuffer.h"
#include "specula/image/image_io.h"

#include <cmath>
#include <string_view>

#ifndef SPECULA_FUZZ_FILE
#error "define SPECULA_FUZZ_FILE (e.g. \"image.png\")"
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path path = specula::fuzz::write_input({data, size}, SPECULA_FUZZ_FILE);
  const bool png = std::string_view(SPECULA_FUZZ_FILE).ends_with(".png");
  specula::fuzz::expect_only_errors([&] {
    const specula::Framebuffer image = specula::read_image(path);
    if (image.width() == 0 || image.height() == 0 ||
        image.width() > specula::kMaxFramebufferSide || image.height() > specula::kMaxFramebufferSide)
      specula::fuzz::finding("read_image returned an image of an impossible size");
    for (const specula::vec3& p : image.pixels())
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(p[c])) specula::fuzz::finding("read_image returned a non-finite value");
        if (png && (p[c] < 0.0f || p[c] > 1.0f))
          specula::fuzz::finding("read_png returned a value outside [0, 1]");
      }
  });
  return 0;
}
