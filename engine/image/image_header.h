#pragma once
/// \file
/// What an image file will cost to read, from its header alone: size, format and a bound on the
/// memory read_image allocates while decoding it. For refusing a request that would not fit
/// before any pixel memory is allocated (`specula compare` of two 16384² images).

#include "specula/image/image_io.h"

#include <cstdint>
#include <filesystem>
#include <optional>

namespace specula {

struct ImageHeader {
  ImageFormat format = ImageFormat::Png;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::uint64_t file_bytes = 0;
  /// A bound on what read_image allocates beyond the framebuffer it returns (12 bytes per
  /// pixel), at its peak: the file's bytes and the decoder's buffers.
  std::uint64_t decode_bytes = 0;
};

/// Reads the header of a .png (signature, IHDR) or .exr file (magic number, version, header
/// attributes up to the end of the header; no pixel data and no allocation sized by the file).
/// Empty when the file cannot be opened, is not of the format its extension names, or its
/// header is malformed or names a size outside [1, kMaxFramebufferSide]: read_image then
/// reports the problem with its own message.
[[nodiscard]] std::optional<ImageHeader> read_image_header(const std::filesystem::path& path);

} // namespace specula
