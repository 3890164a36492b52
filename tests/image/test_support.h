#pragma once
// Helpers shared by the image tests: a per-test temporary folder, seeded random framebuffers,
// raw file bytes, and a minimal PNG encoder (stored deflate blocks) that is independent of the
// stb code under test, so the reader is checked against files it did not write itself.

#include "specula/image/framebuffer.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <unistd.h>

namespace specula::test {

using Bytes = std::vector<std::uint8_t>;

/// A fresh folder for the running test, removed afterwards. Named after the test and the process
/// so parallel ctest runs do not collide.
class TempDir {
public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            ("specula_image_" + std::string(info->test_suite_name()) + "_" + info->name() + "_" +
             std::to_string(::getpid()));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  [[nodiscard]] std::filesystem::path file(const std::string& name) const { return path_ / name; }

private:
  std::filesystem::path path_;
};

/// Every channel uniform in [lo, hi), from a seeded generator.
inline Framebuffer random_image(std::uint32_t width, std::uint32_t height, std::uint32_t seed,
                                float lo = 0.0f, float hi = 1.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> value(lo, hi);
  Framebuffer image(width, height);
  for (vec3& p : image.pixels()) p = vec3(value(rng), value(rng), value(rng));
  return image;
}

inline Bytes read_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

inline void write_bytes(const std::filesystem::path& path, const Bytes& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

// --- A minimal PNG encoder (RFC 2083 / ISO 15948, zlib RFC 1950, deflate RFC 1951) -------------

inline std::uint32_t crc32(const std::uint8_t* data, std::size_t size, std::uint32_t crc = 0) {
  crc = ~crc;
  for (std::size_t i = 0; i < size; ++i) {
    crc ^= data[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

inline void put_be32(Bytes& out, std::uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<std::uint8_t>(v >> shift));
}

inline void put_chunk(Bytes& png, const char type[5], const Bytes& data) {
  put_be32(png, static_cast<std::uint32_t>(data.size()));
  Bytes typed(type, type + 4);
  typed.insert(typed.end(), data.begin(), data.end());
  png.insert(png.end(), typed.begin(), typed.end());
  put_be32(png, crc32(typed.data(), typed.size()));
}

/// The PNG signature and an IHDR chunk (no filtering or interlace).
inline Bytes png_header(std::uint32_t width, std::uint32_t height, int bit_depth, int color_type) {
  Bytes png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  Bytes ihdr;
  put_be32(ihdr, width);
  put_be32(ihdr, height);
  ihdr.push_back(static_cast<std::uint8_t>(bit_depth));
  ihdr.push_back(static_cast<std::uint8_t>(color_type));
  ihdr.push_back(0); // deflate
  ihdr.push_back(0); // adaptive filtering
  ihdr.push_back(0); // no interlace
  put_chunk(png, "IHDR", ihdr);
  return png;
}

/// A complete PNG from raw samples (big-endian for 16 bits, `channels` per pixel, rows top
/// first). color_type: 0 gray, 2 RGB, 4 gray+alpha, 6 RGBA. The zlib stream uses stored blocks.
inline Bytes encode_png(std::uint32_t width, std::uint32_t height, int bit_depth, int color_type,
                        int channels, const Bytes& samples) {
  const std::size_t row_bytes = std::size_t{width} * channels * (bit_depth / 8);
  Bytes raw; // each row: filter type 0, then the samples
  for (std::uint32_t y = 0; y < height; ++y) {
    raw.push_back(0);
    raw.insert(raw.end(), samples.begin() + static_cast<std::ptrdiff_t>(y * row_bytes),
               samples.begin() + static_cast<std::ptrdiff_t>((y + 1) * row_bytes));
  }
  Bytes zlib = {0x78, 0x01};
  for (std::size_t pos = 0; pos < raw.size() || pos == 0;) {
    const std::size_t n = std::min<std::size_t>(65535, raw.size() - pos);
    const bool last = pos + n == raw.size();
    zlib.push_back(last ? 1 : 0); // BFINAL, BTYPE = 00 (stored)
    zlib.push_back(static_cast<std::uint8_t>(n & 0xFF));
    zlib.push_back(static_cast<std::uint8_t>(n >> 8));
    zlib.push_back(static_cast<std::uint8_t>(~n & 0xFF));
    zlib.push_back(static_cast<std::uint8_t>((~n >> 8) & 0xFF));
    zlib.insert(zlib.end(), raw.begin() + static_cast<std::ptrdiff_t>(pos),
                raw.begin() + static_cast<std::ptrdiff_t>(pos + n));
    pos += n;
    if (last) break;
  }
  std::uint32_t a = 1;
  std::uint32_t b = 0;
  for (std::uint8_t v : raw) {
    a = (a + v) % 65521;
    b = (b + a) % 65521;
  }
  put_be32(zlib, (b << 16) | a);

  Bytes png = png_header(width, height, bit_depth, color_type);
  put_chunk(png, "IDAT", zlib);
  put_chunk(png, "IEND", {});
  return png;
}

} // namespace specula::test
