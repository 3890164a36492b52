#include "specula/image/image_io.h"

#include "specula/core/error.h"
#include "specula/image/srgb.h"

// The implementations live in the system libstb; only the declarations are included here.
#include <stb_image.h>
#include <stb_image_write.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace specula {

namespace {

using Bytes = std::vector<std::uint8_t>;

[[noreturn]] void fail(const std::filesystem::path& path, const std::string& message) {
  throw Error(path.string(), message);
}

std::string errno_message() { return std::error_code(errno, std::generic_category()).message(); }

std::string size_text(std::int64_t width, std::int64_t height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

/// The whole file, with the reasons a file cannot be read told apart (a missing file and an
/// empty one are different mistakes for the user).
Bytes read_file_bytes(const std::filesystem::path& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) fail(path, "file not found");
  if (std::filesystem::is_directory(status)) fail(path, "is a directory, not an image file");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open: " + errno_message());
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) fail(path, "cannot read: " + errno_message());
  if (size == 0) fail(path, "empty file");
  in.seekg(0, std::ios::beg);
  Bytes bytes(static_cast<std::size_t>(size));
  in.read(reinterpret_cast<char*>(bytes.data()), size);
  if (in.gcount() != size) fail(path, "cannot read: " + errno_message());
  return bytes;
}

std::string lowercase_extension(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

// --- PNG ---------------------------------------------------------------------------------------

constexpr std::array<std::uint8_t, 8> kPngSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};

std::uint8_t encode_srgb8(float linear) {
  // Round to nearest: the encoded value is in [0, 1], so +0.5 and truncation is exact rounding.
  return static_cast<std::uint8_t>(linear_to_srgb(linear) * 255.0f + 0.5f);
}

/// Owns memory returned by stb_image.
struct StbiFree {
  void operator()(void* p) const noexcept { stbi_image_free(p); }
};

std::string stbi_reason() {
  const char* reason = stbi_failure_reason();
  return reason != nullptr ? reason : "unknown reason";
}

// --- OpenEXR -----------------------------------------------------------------------------------
// Everything below follows "OpenEXR File Layout" (openexr.com/en/latest/OpenEXRFileLayout.html):
// magic number, version field, header (attributes terminated by a null byte), line offset table
// (one uint64 per scan-line block, from the start of the file), then the blocks. All integers and
// floats are little-endian; they are packed byte by byte so the code is independent of the host.

constexpr std::array<std::uint8_t, 4> kExrMagic = {0x76, 0x2F, 0x31, 0x01}; // 20000630 LE
constexpr std::uint32_t kExrVersion = 2;
constexpr std::uint32_t kExrFlagTiled = 0x200;
constexpr std::uint32_t kExrFlagLongNames = 0x400;
constexpr std::uint32_t kExrFlagNonImage = 0x800; // deep data
constexpr std::uint32_t kExrFlagMultipart = 0x1000;
constexpr std::int32_t kExrPixelUint = 0;
constexpr std::int32_t kExrPixelHalf = 1;
constexpr std::int32_t kExrPixelFloat = 2;

class ByteWriter {
public:
  void u8(std::uint8_t v) { bytes_.push_back(v); }
  void u32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) u8(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
  void u64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) u8(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
  void text(std::string_view s) { // null-terminated
    bytes_.insert(bytes_.end(), s.begin(), s.end());
    u8(0);
  }
  void append(const Bytes& other) { bytes_.insert(bytes_.end(), other.begin(), other.end()); }
  [[nodiscard]] const Bytes& bytes() const { return bytes_; }
  [[nodiscard]] std::size_t size() const { return bytes_.size(); }

private:
  Bytes bytes_;
};

/// One header attribute: name, type name, int32 size, value.
void write_attribute(ByteWriter& out, std::string_view name, std::string_view type,
                     const ByteWriter& value) {
  out.text(name);
  out.text(type);
  out.i32(static_cast<std::int32_t>(value.size()));
  out.append(value.bytes());
}

/// Bounds-checked little-endian reads; running past the end is a truncated file.
class ByteReader {
public:
  ByteReader(std::span<const std::uint8_t> bytes, const std::filesystem::path& path,
             std::size_t position = 0)
      : bytes_(bytes), path_(path), position_(position) {}

  [[nodiscard]] std::size_t position() const { return position_; }
  [[nodiscard]] std::size_t remaining() const { return bytes_.size() - position_; }

  void need(std::size_t n, const char* what) const {
    if (n > remaining()) fail(path_, std::string("truncated EXR: file ends inside the ") + what);
  }
  std::uint8_t u8(const char* what) {
    need(1, what);
    return bytes_[position_++];
  }
  std::uint32_t u32(const char* what) {
    need(4, what);
    std::uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= std::uint32_t{bytes_[position_++]} << (8 * i);
    return v;
  }
  std::int32_t i32(const char* what) { return static_cast<std::int32_t>(u32(what)); }
  std::uint64_t u64(const char* what) {
    need(8, what);
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= std::uint64_t{bytes_[position_++]} << (8 * i);
    return v;
  }
  /// A null-terminated string of at most max_length characters.
  std::string text(std::size_t max_length, const char* what) {
    std::string s;
    for (;;) {
      const std::uint8_t c = u8(what);
      if (c == 0) return s;
      if (s.size() == max_length) {
        fail(path_, std::string("corrupt EXR: unterminated or over-long name in the ") + what);
      }
      s.push_back(static_cast<char>(c));
    }
  }
  std::span<const std::uint8_t> take(std::size_t n, const char* what) {
    need(n, what);
    const auto s = bytes_.subspan(position_, n);
    position_ += n;
    return s;
  }

private:
  std::span<const std::uint8_t> bytes_;
  const std::filesystem::path& path_;
  std::size_t position_;
};

/// IEEE 754 binary16 → binary32, exact (every half is a float), subnormals, ±Inf and NaN kept.
float half_to_float(std::uint16_t h) {
  const std::uint32_t sign = (h >> 15) & 0x1u;
  const std::uint32_t exponent = (h >> 10) & 0x1Fu;
  const std::uint32_t mantissa = h & 0x3FFu;
  float magnitude;
  if (exponent == 0) {
    magnitude = std::ldexp(static_cast<float>(mantissa), -24); // subnormal: m · 2^-24
  } else if (exponent == 31) {
    magnitude = mantissa == 0 ? std::numeric_limits<float>::infinity()
                              : std::numeric_limits<float>::quiet_NaN();
  } else {
    magnitude = std::ldexp(static_cast<float>(mantissa | 0x400u), static_cast<int>(exponent) - 25);
  }
  return sign != 0 ? -magnitude : magnitude;
}

const char* compression_name(std::uint8_t c) {
  constexpr std::array<const char*, 10> kNames = {"NO_COMPRESSION", "RLE", "ZIPS", "ZIP",  "PIZ",
                                                  "PXR24",          "B44", "B44A", "DWAA", "DWAB"};
  return c < kNames.size() ? kNames[c] : "unknown";
}

struct ExrChannel {
  std::string name;
  std::int32_t pixel_type = 0;
  std::size_t offset_in_line = 0; ///< byte offset of this channel's samples in a scan line
};

struct ExrHeader {
  std::vector<ExrChannel> channels;
  std::optional<std::uint8_t> compression;
  std::optional<std::array<std::int32_t, 4>> data_window; ///< xMin, yMin, xMax, yMax
};

std::size_t pixel_type_size(std::int32_t type) { return type == kExrPixelHalf ? 2 : 4; }

void expect_type(const std::filesystem::path& path, const std::string& name,
                 const std::string& type, const char* expected, std::size_t size,
                 std::size_t expected_size) {
  if (type != expected) {
    fail(path, "corrupt EXR: attribute " + name + " has type " + type + ", expected " + expected);
  }
  if (expected_size != 0 && size != expected_size) {
    fail(path, "corrupt EXR: attribute " + name + " has size " + std::to_string(size) +
                   ", expected " + std::to_string(expected_size));
  }
}

std::vector<ExrChannel> parse_channel_list(std::span<const std::uint8_t> value,
                                           std::size_t max_name,
                                           const std::filesystem::path& path) {
  ByteReader in(value, path);
  std::vector<ExrChannel> channels;
  for (;;) {
    std::string name = in.text(max_name, "channel list");
    if (name.empty()) break;
    ExrChannel channel;
    channel.name = std::move(name);
    channel.pixel_type = in.i32("channel list");
    in.u8("channel list");      // pLinear: a hint for lossy compressors, irrelevant here
    in.take(3, "channel list"); // reserved
    const std::int32_t x_sampling = in.i32("channel list");
    const std::int32_t y_sampling = in.i32("channel list");
    if (channel.pixel_type < kExrPixelUint || channel.pixel_type > kExrPixelFloat) {
      fail(path, "corrupt EXR: channel " + channel.name + " has pixel type " +
                     std::to_string(channel.pixel_type));
    }
    if (x_sampling != 1 || y_sampling != 1) {
      fail(path, "unsupported EXR: channel " + channel.name + " is subsampled (" +
                     std::to_string(x_sampling) + "x" + std::to_string(y_sampling) + ")");
    }
    channels.push_back(std::move(channel));
  }
  if (channels.empty()) fail(path, "corrupt EXR: the channel list is empty");
  return channels;
}

} // namespace

// --- PNG ---------------------------------------------------------------------------------------

void write_png_srgb8(std::span<const std::uint8_t> rgb, std::uint32_t width, std::uint32_t height,
                     const std::filesystem::path& path) {
  if (width == 0 || height == 0 || width > kMaxFramebufferSide || height > kMaxFramebufferSide ||
      rgb.size() != std::size_t{3} * width * height) {
    fail(path, "cannot write PNG: " + std::to_string(rgb.size()) + " bytes do not form a " +
                   size_text(width, height) + " RGB image");
  }
  const int stride = static_cast<int>(3 * width);
  if (stbi_write_png(path.string().c_str(), static_cast<int>(width), static_cast<int>(height), 3,
                     rgb.data(), stride) == 0) {
    fail(path, "cannot write PNG: " + errno_message());
  }
}

void write_png(const Framebuffer& image, const std::filesystem::path& path) {
  std::vector<std::uint8_t> rgb(3 * image.pixel_count());
  std::size_t i = 0;
  for (const vec3& p : image.pixels()) {
    rgb[i++] = encode_srgb8(p.r);
    rgb[i++] = encode_srgb8(p.g);
    rgb[i++] = encode_srgb8(p.b);
  }
  write_png_srgb8(rgb, image.width(), image.height(), path);
}

Framebuffer read_png(const std::filesystem::path& path) {
  const Bytes bytes = read_file_bytes(path);
  if (bytes.size() < kPngSignature.size() ||
      !std::equal(kPngSignature.begin(), kPngSignature.end(), bytes.begin())) {
    fail(path, "not a PNG file (wrong signature)");
  }
  if (bytes.size() > static_cast<std::size_t>(INT_MAX)) fail(path, "PNG file larger than 2 GiB");
  const auto* data = bytes.data();
  const int length = static_cast<int>(bytes.size());

  // The size is read from IHDR here rather than through stb, which reports an oversized image
  // only as "unknown image type"; checked before decoding, so a forged IHDR cannot make stb
  // allocate gigabytes. IHDR must be the first chunk: length 13, type, width, height (ISO 15948).
  constexpr std::array<std::uint8_t, 8> kIhdrStart = {0, 0, 0, 13, 'I', 'H', 'D', 'R'};
  if (bytes.size() < 24 || !std::equal(kIhdrStart.begin(), kIhdrStart.end(), bytes.begin() + 8)) {
    fail(path, "corrupt or truncated PNG: no IHDR chunk after the signature");
  }
  const auto be32 = [&](std::size_t at) {
    return std::uint64_t{bytes[at]} << 24 | std::uint64_t{bytes[at + 1]} << 16 |
           std::uint64_t{bytes[at + 2]} << 8 | std::uint64_t{bytes[at + 3]};
  };
  const std::uint64_t ihdr_width = be32(16);
  const std::uint64_t ihdr_height = be32(20);
  if (ihdr_width == 0 || ihdr_height == 0 || ihdr_width > kMaxFramebufferSide ||
      ihdr_height > kMaxFramebufferSide) {
    fail(path, "PNG size " +
                   size_text(static_cast<std::int64_t>(ihdr_width),
                             static_cast<std::int64_t>(ihdr_height)) +
                   " is outside [1, " + std::to_string(kMaxFramebufferSide) + "] per side");
  }

  int width = 0;
  int height = 0;
  int channels_in_file = 0;
  if (stbi_info_from_memory(data, length, &width, &height, &channels_in_file) == 0) {
    fail(path, "corrupt PNG: " + stbi_reason());
  }
  if (static_cast<std::uint64_t>(width) != ihdr_width ||
      static_cast<std::uint64_t>(height) != ihdr_height) {
    fail(path, "corrupt PNG: inconsistent size in IHDR");
  }

  Framebuffer image(static_cast<std::uint32_t>(width), static_cast<std::uint32_t>(height));
  auto pixels = image.pixels();
  int w = 0;
  int h = 0;
  int n = 0;
  if (stbi_is_16_bit_from_memory(data, length) != 0) {
    std::unique_ptr<stbi_us, StbiFree> decoded(
        stbi_load_16_from_memory(data, length, &w, &h, &n, 3));
    if (!decoded) fail(path, "corrupt or truncated PNG: " + stbi_reason());
    for (std::size_t i = 0; i < pixels.size(); ++i) {
      for (int c = 0; c < 3; ++c) {
        pixels[i][c] = srgb_to_linear(static_cast<float>(decoded.get()[3 * i + c]) / 65535.0f);
      }
    }
  } else {
    std::unique_ptr<stbi_uc, StbiFree> decoded(stbi_load_from_memory(data, length, &w, &h, &n, 3));
    if (!decoded) fail(path, "corrupt or truncated PNG: " + stbi_reason());
    std::array<float, 256> to_linear{};
    for (int v = 0; v < 256; ++v) to_linear[v] = srgb_to_linear(static_cast<float>(v) / 255.0f);
    for (std::size_t i = 0; i < pixels.size(); ++i) {
      for (int c = 0; c < 3; ++c) pixels[i][c] = to_linear[decoded.get()[3 * i + c]];
    }
  }
  if (w != width || h != height) fail(path, "corrupt PNG: header and image data disagree on size");
  return image;
}

// --- OpenEXR -----------------------------------------------------------------------------------

void write_exr(const Framebuffer& image, const std::filesystem::path& path) {
  const std::uint32_t width = image.width();
  const std::uint32_t height = image.height();
  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      const vec3& p = image.at(x, y);
      if (!std::isfinite(p.r) || !std::isfinite(p.g) || !std::isfinite(p.b)) {
        fail(path, "cannot write EXR: pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                       ") is NaN or infinite");
      }
    }
  }

  // Header attributes, in the name order OpenEXR itself writes them.
  ByteWriter header;
  for (std::uint8_t b : kExrMagic) header.u8(b);
  header.u32(kExrVersion); // single-part scan-line file, short names: no flag bits
  {
    ByteWriter channels; // chlist: sorted by name, as the format requires
    for (const char* name : {"B", "G", "R"}) {
      channels.text(name);
      channels.i32(kExrPixelFloat);
      channels.u8(0);                             // pLinear
      for (int i = 0; i < 3; ++i) channels.u8(0); // reserved
      channels.i32(1);                            // xSampling
      channels.i32(1);                            // ySampling
    }
    channels.u8(0);
    write_attribute(header, "channels", "chlist", channels);
  }
  {
    ByteWriter compression;
    compression.u8(0); // NO_COMPRESSION
    write_attribute(header, "compression", "compression", compression);
  }
  ByteWriter window; // box2i: xMin, yMin, xMax, yMax (inclusive)
  window.i32(0);
  window.i32(0);
  window.i32(static_cast<std::int32_t>(width - 1));
  window.i32(static_cast<std::int32_t>(height - 1));
  write_attribute(header, "dataWindow", "box2i", window);
  write_attribute(header, "displayWindow", "box2i", window);
  {
    ByteWriter line_order;
    line_order.u8(0); // INCREASING_Y
    write_attribute(header, "lineOrder", "lineOrder", line_order);
  }
  {
    ByteWriter aspect;
    aspect.f32(1.0f);
    write_attribute(header, "pixelAspectRatio", "float", aspect);
  }
  {
    ByteWriter center;
    center.f32(0.0f);
    center.f32(0.0f);
    write_attribute(header, "screenWindowCenter", "v2f", center);
  }
  {
    ByteWriter screen_width;
    screen_width.f32(1.0f);
    write_attribute(header, "screenWindowWidth", "float", screen_width);
  }
  header.u8(0); // end of header

  // Line offset table: block y starts after the table and the y blocks before it.
  const std::uint64_t line_bytes = std::uint64_t{width} * 3 * sizeof(float);
  const std::uint64_t block_bytes = 2 * sizeof(std::int32_t) + line_bytes;
  const std::uint64_t first_block = header.size() + std::uint64_t{height} * sizeof(std::uint64_t);
  for (std::uint32_t y = 0; y < height; ++y) header.u64(first_block + y * block_bytes);

  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) fail(path, "cannot write EXR: " + errno_message());
  out.write(reinterpret_cast<const char*>(header.bytes().data()),
            static_cast<std::streamsize>(header.size()));
  ByteWriter block;
  for (std::uint32_t y = 0; y < height; ++y) {
    block = ByteWriter();
    block.i32(static_cast<std::int32_t>(y));
    block.i32(static_cast<std::int32_t>(line_bytes));
    for (int channel : {2, 1, 0}) { // B, G, R: the channel list order
      for (std::uint32_t x = 0; x < width; ++x) block.f32(image.at(x, y)[channel]);
    }
    out.write(reinterpret_cast<const char*>(block.bytes().data()),
              static_cast<std::streamsize>(block.size()));
  }
  out.flush();
  if (!out) fail(path, "cannot write EXR: " + errno_message());
}

Framebuffer read_exr(const std::filesystem::path& path) {
  const Bytes bytes = read_file_bytes(path);
  if (bytes.size() < kExrMagic.size() ||
      !std::equal(kExrMagic.begin(), kExrMagic.end(), bytes.begin())) {
    fail(path, "not an OpenEXR file (wrong magic number)");
  }
  ByteReader in(bytes, path, kExrMagic.size());

  // Version field: the low byte is the format version, the rest are feature flags.
  const std::uint32_t version = in.u32("version field");
  if ((version & 0xFFu) != kExrVersion) {
    fail(path, "unsupported EXR: format version " + std::to_string(version & 0xFFu));
  }
  if ((version & kExrFlagMultipart) != 0) fail(path, "unsupported EXR: multi-part file");
  if ((version & kExrFlagNonImage) != 0) fail(path, "unsupported EXR: deep data");
  if ((version & kExrFlagTiled) != 0) fail(path, "unsupported EXR: tiled image");
  if ((version & ~(0xFFu | kExrFlagLongNames)) != 0) {
    fail(path, "unsupported EXR: unknown version flags " + std::to_string(version >> 8));
  }
  const std::size_t max_name = (version & kExrFlagLongNames) != 0 ? 255 : 31;

  // Header: attributes until an empty name; unknown ones are skipped by their size.
  ExrHeader header;
  for (;;) {
    const std::string name = in.text(max_name, "header");
    if (name.empty()) break;
    const std::string type = in.text(max_name, "header");
    const std::int32_t size = in.i32("header");
    if (size < 0) fail(path, "corrupt EXR: attribute " + name + " has negative size");
    const auto value = in.take(static_cast<std::size_t>(size), "header");
    const auto value_size = static_cast<std::size_t>(size);
    if (name == "channels") {
      expect_type(path, name, type, "chlist", value_size, 0);
      header.channels = parse_channel_list(value, max_name, path);
    } else if (name == "compression") {
      expect_type(path, name, type, "compression", value_size, 1);
      header.compression = value[0];
    } else if (name == "dataWindow") {
      expect_type(path, name, type, "box2i", value_size, 16);
      ByteReader box(value, path);
      std::array<std::int32_t, 4> window{};
      for (auto& v : window) v = box.i32("dataWindow");
      header.data_window = window;
    }
  }
  if (header.channels.empty()) fail(path, "corrupt EXR: header has no channels attribute");
  if (!header.compression) fail(path, "corrupt EXR: header has no compression attribute");
  if (!header.data_window) fail(path, "corrupt EXR: header has no dataWindow attribute");
  if (*header.compression != 0) {
    fail(path, std::string("unsupported EXR: compression ") +
                   compression_name(*header.compression) + " (only NO_COMPRESSION is read)");
  }

  // Sizes in 64 bits: a forged window of ±2^31 must not overflow before it is rejected.
  const auto [x_min, y_min, x_max, y_max] = *header.data_window;
  const std::int64_t width = std::int64_t{x_max} - x_min + 1;
  const std::int64_t height = std::int64_t{y_max} - y_min + 1;
  if (width < 1 || height < 1) {
    fail(path, "corrupt EXR: empty data window (" + size_text(width, height) + ")");
  }
  if (width > kMaxFramebufferSide || height > kMaxFramebufferSide) {
    fail(path, "EXR size " + size_text(width, height) + " is outside [1, " +
                   std::to_string(kMaxFramebufferSide) + "] per side");
  }

  // Where each of R, G, B lies in a scan line: channels are stored one after another, each as
  // `width` samples, in channel-list order.
  constexpr std::array<std::string_view, 3> kRgbNames = {"R", "G", "B"};
  std::size_t line_bytes = 0;
  std::array<const ExrChannel*, 3> rgb{};
  for (ExrChannel& channel : header.channels) {
    channel.offset_in_line = line_bytes;
    line_bytes += static_cast<std::size_t>(width) * pixel_type_size(channel.pixel_type);
    for (int c = 0; c < 3; ++c) {
      if (channel.name == kRgbNames[c]) rgb[c] = &channel;
    }
  }
  for (int c = 0; c < 3; ++c) {
    if (rgb[c] == nullptr) {
      std::string found;
      for (const ExrChannel& channel : header.channels) found += " " + channel.name;
      fail(path, "unsupported EXR: no R, G and B channels (found:" + found + ")");
    }
    if (rgb[c]->pixel_type == kExrPixelUint) {
      fail(path, "unsupported EXR: channel " + rgb[c]->name + " is UINT, not HALF or FLOAT");
    }
  }

  // Line offset table, then one block per scan line, found through the table so any line
  // order is read the same way.
  const auto rows = static_cast<std::size_t>(height);
  std::vector<std::uint64_t> offsets(rows);
  for (auto& offset : offsets) offset = in.u64("line offset table");
  const std::size_t blocks_start = in.position();

  Framebuffer image(static_cast<std::uint32_t>(width), static_cast<std::uint32_t>(height));
  std::vector<bool> seen(rows, false);
  for (std::size_t i = 0; i < rows; ++i) {
    if (offsets[i] < blocks_start || offsets[i] >= bytes.size()) {
      fail(path, "truncated or corrupt EXR: scan line block " + std::to_string(i) + " has offset " +
                     std::to_string(offsets[i]) + " outside the file");
    }
    ByteReader block(bytes, path, static_cast<std::size_t>(offsets[i]));
    const std::int32_t y = block.i32("scan line block");
    const std::int32_t size = block.i32("scan line block");
    if (y < y_min || y > y_max) {
      fail(path, "corrupt EXR: scan line y = " + std::to_string(y) + " outside the data window");
    }
    const auto row = static_cast<std::size_t>(std::int64_t{y} - y_min);
    if (seen[row]) fail(path, "corrupt EXR: scan line y = " + std::to_string(y) + " appears twice");
    seen[row] = true;
    if (size < 0 || static_cast<std::size_t>(size) != line_bytes) {
      fail(path, "corrupt EXR: scan line y = " + std::to_string(y) + " holds " +
                     std::to_string(size) + " bytes, expected " + std::to_string(line_bytes));
    }
    const auto data = block.take(line_bytes, "scan line data");
    for (int c = 0; c < 3; ++c) {
      const ExrChannel& channel = *rgb[c];
      ByteReader samples(data, path, channel.offset_in_line);
      for (std::size_t x = 0; x < static_cast<std::size_t>(width); ++x) {
        float v;
        if (channel.pixel_type == kExrPixelHalf) {
          const std::uint32_t lo = samples.u8("scan line data");
          const std::uint32_t hi = samples.u8("scan line data");
          v = half_to_float(static_cast<std::uint16_t>(lo | (hi << 8)));
        } else {
          v = std::bit_cast<float>(samples.u32("scan line data"));
        }
        if (!std::isfinite(v)) {
          fail(path, "EXR pixel (" + std::to_string(x) + ", " + std::to_string(row) + ") channel " +
                         channel.name + " is NaN or infinite");
        }
        image.at(static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(row))[c] = v;
      }
    }
  }
  return image;
}

// --- By extension ------------------------------------------------------------------------------

Framebuffer read_image(const std::filesystem::path& path) {
  const std::string extension = lowercase_extension(path);
  if (extension == ".png") return read_png(path);
  if (extension == ".exr") return read_exr(path);
  fail(path,
       "unsupported image extension '" + path.extension().string() + "' (expected .png or .exr)");
}

void write_image(const Framebuffer& image, const std::filesystem::path& path) {
  const std::string extension = lowercase_extension(path);
  if (extension == ".png") return write_png(image, path);
  if (extension == ".exr") return write_exr(image, path);
  fail(path,
       "unsupported image extension '" + path.extension().string() + "' (expected .png or .exr)");
}

} // namespace specula
