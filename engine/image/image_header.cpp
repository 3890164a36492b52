#include "specula/image/image_header.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <fstream>
#include <string>
#include <system_error>

namespace specula {

namespace {

std::uint32_t be32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} << 24 | std::uint32_t{p[1]} << 16 | std::uint32_t{p[2]} << 8 | p[3];
}
std::uint32_t le32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
         std::uint32_t{p[3]} << 24;
}

bool valid_size(std::int64_t width, std::int64_t height) {
  return width >= 1 && height >= 1 && width <= kMaxFramebufferSide && height <= kMaxFramebufferSide;
}

/// PNG (ISO 15948): signature, then IHDR with width, height, bit depth and colour type.
/// read_png holds the file, stb collects the IDAT data (into a buffer grown by doubling: up to
/// twice the file), inflates it (one filter byte per row and up to 4 channels of 1 or 2 bytes)
/// and unfilters it into an image of up to 4 channels, converted to 3 channels at the end; the
/// inflated and unfiltered buffers are the largest pair alive at once.
std::optional<ImageHeader> png_header(std::ifstream& in, std::uint64_t file_bytes) {
  std::array<std::uint8_t, 26> head{};
  if (!in.read(reinterpret_cast<char*>(head.data()), head.size())) return std::nullopt;
  constexpr std::array<std::uint8_t, 16> kStart = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n',
                                                   0,    0,   0,   13,  'I',  'H',  'D',  'R'};
  if (!std::equal(kStart.begin(), kStart.end(), head.begin())) return std::nullopt;
  const std::uint32_t width = be32(&head[16]);
  const std::uint32_t height = be32(&head[20]);
  if (!valid_size(width, height)) return std::nullopt;
  const std::uint64_t channel_bytes = head[24] == 16 ? 2 : 1;
  const std::uint64_t pixels = std::uint64_t{width} * height;
  ImageHeader h{ImageFormat::Png, width, height, file_bytes, 0};
  h.decode_bytes = 3 * file_bytes + 2 * 4 * channel_bytes * pixels + height;
  return h;
}

/// OpenEXR: magic number, version, then attributes (name, type, size, value) up to an empty name.
/// read_exr holds the file and decodes one chunk (a group of scan lines or a tile) at a time,
/// twice (a check through OpenEXRCore, then the C++ library), each time with a few buffers of the
/// chunk's size: a bound of 4 buffers of 4 channels of 4 bytes per chunk pixel.
std::optional<ImageHeader> exr_header(std::ifstream& in, std::uint64_t file_bytes) {
  std::array<std::uint8_t, 8> head{};
  if (!in.read(reinterpret_cast<char*>(head.data()), head.size())) return std::nullopt;
  if (le32(head.data()) != 20000630u) return std::nullopt;
  const bool tiled = (le32(&head[4]) & 0x200u) != 0;
  std::optional<std::array<std::int32_t, 4>> window;
  int compression = -1;
  std::uint64_t tile_pixels = 0;
  const auto read_text = [&](std::string& text) {
    text.clear();
    for (char c = 0; in.get(c) && c != '\0';) {
      if (text.size() == 255) return false; // names and types are at most 255 bytes
      text += c;
    }
    return bool(in);
  };
  std::string name;
  std::string type;
  std::uint64_t at = head.size();
  for (int attributes = 0; attributes < 100000; ++attributes) {
    if (!read_text(name)) return std::nullopt;
    if (name.empty()) break; // end of the header
    if (!read_text(type)) return std::nullopt;
    std::array<std::uint8_t, 4> size_field{};
    if (!in.read(reinterpret_cast<char*>(size_field.data()), 4)) return std::nullopt;
    const std::uint32_t size = le32(size_field.data());
    at += name.size() + type.size() + 2 + 4;
    if (size > file_bytes - std::min(at, file_bytes)) return std::nullopt;
    std::array<std::uint8_t, 16> value{};
    const std::uint32_t kept = std::min<std::uint32_t>(size, value.size());
    if (!in.read(reinterpret_cast<char*>(value.data()), kept)) return std::nullopt;
    in.seekg(size - kept, std::ios::cur);
    at += size;
    if (name == "dataWindow" && type == "box2i" && size == 16) {
      window = std::array<std::int32_t, 4>{};
      for (std::size_t k = 0; k < 4; ++k)
        (*window)[k] = static_cast<std::int32_t>(le32(&value[4 * k]));
    } else if (name == "compression" && type == "compression" && size == 1) {
      compression = value[0];
    } else if (name == "tiles" && type == "tiledesc" && size == 9) {
      tile_pixels = std::uint64_t{le32(&value[0])} * le32(&value[4]);
    }
  }
  if (!window) return std::nullopt;
  const std::int64_t width = std::int64_t{(*window)[2]} - (*window)[0] + 1;
  const std::int64_t height = std::int64_t{(*window)[3]} - (*window)[1] + 1;
  if (!valid_size(width, height)) return std::nullopt;
  // Scan lines per chunk by compression (OpenEXR file layout): NONE, RLE, ZIPS 1; ZIP, PXR24 16;
  // PIZ, B44, B44A, DWAA 32; DWAB 256.
  std::uint64_t lines = 256;
  if (compression >= 0 && compression <= 2) lines = 1;
  if (compression == 3 || compression == 5) lines = 16;
  if (compression == 4 || compression == 6 || compression == 7 || compression == 8) lines = 32;
  const std::uint64_t pixels = std::uint64_t(width) * std::uint64_t(height);
  const std::uint64_t chunk_pixels =
      std::min(pixels, tiled && tile_pixels > 0 ? tile_pixels : lines * std::uint64_t(width));
  ImageHeader h{ImageFormat::Exr, static_cast<std::uint32_t>(width),
                static_cast<std::uint32_t>(height), file_bytes, 0};
  h.decode_bytes = file_bytes + 4 * 4 * 4 * chunk_pixels;
  return h;
}

} // namespace

std::optional<ImageHeader> read_image_header(const std::filesystem::path& path) {
  const std::optional<ImageFormat> format = image_format(path);
  std::error_code ec;
  if (!format || !std::filesystem::is_regular_file(path, ec)) return std::nullopt;
  const std::uintmax_t file_bytes = std::filesystem::file_size(path, ec);
  if (ec) return std::nullopt;
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  return *format == ImageFormat::Png ? png_header(in, file_bytes) : exr_header(in, file_bytes);
}

} // namespace specula
