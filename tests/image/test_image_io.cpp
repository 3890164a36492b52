// PNG and OpenEXR files: round trips, every PNG colour type, EXR files written by the OpenEXR
// library in every compression, pixel type and layout the reader accepts, hand-made EXR files
// (independent of the library), and bad files of every kind, including seeded corruptions of
// compressed files, each of which must throw specula::Error naming the file.

#include "specula/core/error.h"
#include "specula/image/image_io.h"
#include "specula/image/srgb.h"
#include "test_support.h"

#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfMultiPartOutputFile.h>
#include <ImfOutputFile.h>
#include <ImfOutputPart.h>
#include <ImfPartType.h>
#include <ImfTiledOutputFile.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace specula {
namespace {

using test::Bytes;
using test::TempDir;

/// Runs `read` and expects a specula::Error whose what() names the file and contains `needle`.
template <class Read>
void expect_error(Read read, const std::filesystem::path& path, const std::string& needle = "") {
  try {
    read(path);
    ADD_FAILURE() << "no error for " << path;
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path.filename().string()), std::string::npos) << what;
    EXPECT_NE(what.find(needle), std::string::npos) << "expected '" << needle << "' in: " << what;
  }
}

void expect_png_error(const std::filesystem::path& path, const std::string& needle = "") {
  expect_error([](const std::filesystem::path& p) { return read_png(p); }, path, needle);
}

void expect_exr_error(const std::filesystem::path& path, const std::string& needle = "") {
  expect_error([](const std::filesystem::path& p) { return read_exr(p); }, path, needle);
}

// --- PNG -----------------------------------------------------------------------------------------

TEST(Png, RoundTripWithinOneLevelInSrgbSpace) {
  TempDir dir;
  // Odd sizes and values outside [0, 1], which the writer must clamp.
  const Framebuffer original = test::random_image(37, 23, 1234, -0.2f, 1.3f);
  write_png(original, dir.file("round.png"));
  const Framebuffer back = read_png(dir.file("round.png"));
  ASSERT_EQ(back.width(), original.width());
  ASSERT_EQ(back.height(), original.height());
  float worst = 0.0f;
  for (std::size_t i = 0; i < original.pixel_count(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const float expected = linear_to_srgb(original.pixels()[i][c]);
      const float got = linear_to_srgb(back.pixels()[i][c]);
      worst = std::max(worst, std::abs(expected - got));
    }
  }
  // Rounding to the nearest of 256 levels: at most half a level, plus float noise.
  EXPECT_LE(worst, 0.5f / 255.0f + 1e-5f);
}

TEST(Png, EightBitLevelsSurviveExactly) {
  // Every 8-bit level decoded and re-encoded gives the same byte: the OETF and EOTF are inverse
  // and the writer rounds to nearest.
  TempDir dir;
  Framebuffer image(256, 1);
  for (std::uint32_t v = 0; v < 256; ++v) {
    image.at(v, 0) = vec3(srgb_to_linear(static_cast<float>(v) / 255.0f));
  }
  write_png(image, dir.file("levels.png"));
  const Framebuffer back = read_png(dir.file("levels.png"));
  EXPECT_EQ(back, image);
}

TEST(Png, ReadsEveryColourTypeAndSixteenBits) {
  TempDir dir;
  const auto eotf8 = [](int v) { return srgb_to_linear(static_cast<float>(v) / 255.0f); };
  const auto eotf16 = [](int v) { return srgb_to_linear(static_cast<float>(v) / 65535.0f); };

  // 2x1 images: gray, gray+alpha, RGB, RGBA at 8 bits; gray and RGB at 16 bits.
  test::write_bytes(dir.file("gray8.png"), test::encode_png(2, 1, 8, 0, 1, {10, 188}));
  test::write_bytes(dir.file("ga8.png"), test::encode_png(2, 1, 8, 4, 2, {10, 0, 188, 255}));
  test::write_bytes(dir.file("rgb8.png"),
                    test::encode_png(2, 1, 8, 2, 3, {1, 2, 3, 250, 251, 252}));
  test::write_bytes(dir.file("rgba8.png"),
                    test::encode_png(2, 1, 8, 6, 4, {1, 2, 3, 0, 250, 251, 252, 77}));
  test::write_bytes(dir.file("gray16.png"),
                    test::encode_png(2, 1, 16, 0, 1, {0x80, 0x00, 0xFF, 0xFF}));
  test::write_bytes(
      dir.file("rgb16.png"),
      test::encode_png(2, 1, 16, 2, 3, {0x00, 0x01, 0x12, 0x34, 0xFF, 0xFE, 0, 0, 0, 0, 0, 0}));

  for (const char* name : {"gray8.png", "ga8.png"}) {
    const Framebuffer g = read_png(dir.file(name));
    EXPECT_EQ(g.at(0, 0), vec3(eotf8(10))) << name;
    EXPECT_EQ(g.at(1, 0), vec3(eotf8(188))) << name;
  }
  // sRGB 188 is about half the linear intensity: checks the direction of the transfer function.
  EXPECT_NEAR(eotf8(188), 0.5f, 0.01f);
  for (const char* name : {"rgb8.png", "rgba8.png"}) { // alpha dropped, not composited
    const Framebuffer c = read_png(dir.file(name));
    EXPECT_EQ(c.at(0, 0), vec3(eotf8(1), eotf8(2), eotf8(3))) << name;
    EXPECT_EQ(c.at(1, 0), vec3(eotf8(250), eotf8(251), eotf8(252))) << name;
  }
  const Framebuffer g16 = read_png(dir.file("gray16.png"));
  EXPECT_EQ(g16.at(0, 0), vec3(eotf16(0x8000)));
  EXPECT_EQ(g16.at(1, 0), vec3(1.0f));
  const Framebuffer c16 = read_png(dir.file("rgb16.png"));
  EXPECT_EQ(c16.at(0, 0), vec3(eotf16(0x0001), eotf16(0x1234), eotf16(0xFFFE)));
  EXPECT_EQ(c16.at(1, 0), vec3(0.0f));
}

TEST(Png, BadFilesThrowErrorsNamingTheFile) {
  TempDir dir;
  expect_png_error(dir.file("missing.png"), "not found");
  test::write_bytes(dir.file("empty.png"), {});
  expect_png_error(dir.file("empty.png"), "empty");
  test::write_bytes(dir.file("text.png"), Bytes{'h', 'e', 'l', 'l', 'o', ' ', 'p', 'n', 'g', '\n'});
  expect_png_error(dir.file("text.png"), "signature");
  test::write_bytes(dir.file("short.png"), Bytes{0x89, 'P', 'N'});
  expect_png_error(dir.file("short.png"), "signature");
  std::filesystem::create_directory(dir.file("folder.png"));
  expect_png_error(dir.file("folder.png"), "directory");

  // Truncations of a valid file: inside IHDR, right after it, and halfway through the data.
  write_png(test::random_image(64, 64, 7), dir.file("valid.png"));
  const Bytes valid = test::read_bytes(dir.file("valid.png"));
  for (std::size_t size : {std::size_t{12}, std::size_t{20}, std::size_t{33}, valid.size() / 2}) {
    const auto name = "cut" + std::to_string(size) + ".png";
    test::write_bytes(dir.file(name),
                      Bytes(valid.begin(), valid.begin() + static_cast<long>(size)));
    expect_png_error(dir.file(name));
  }

  // A header forging 100000 x 100000 pixels must be rejected before any allocation.
  Bytes huge = test::png_header(100000, 100000, 8, 2);
  test::put_chunk(huge, "IEND", {});
  test::write_bytes(dir.file("huge.png"), huge);
  expect_png_error(dir.file("huge.png"), "100000x100000");

  // Valid framing around a zlib stream that is garbage.
  Bytes garbage = test::png_header(4, 4, 8, 2);
  test::put_chunk(garbage, "IDAT", Bytes(40, 0xAB));
  test::put_chunk(garbage, "IEND", {});
  test::write_bytes(dir.file("garbage.png"), garbage);
  expect_png_error(dir.file("garbage.png"));
}

// stb_image grows its buffer to a chunk's declared length before reading it: any chunk whose
// declared length does not fit in the file is refused first (a fuzzer finding: 93 bytes asked
// for 1 GiB). Each chunk type and several lengths, on a file otherwise valid.
TEST(Png, ChunkLengthsBeyondTheFileAreRefusedBeforeDecoding) {
  TempDir dir;
  for (const char* type : {"IDAT", "PLTE", "tEXt", "zzZz"}) {
    for (const std::uint32_t length : {1000U, 0x00100000U, 0x4154000bU, 0x7fffffffU, 0xffffffffU}) {
      Bytes bytes = test::png_header(4, 4, 8, 2);
      test::put_chunk(bytes, type, Bytes(40, 0x11));
      test::put_chunk(bytes, "IEND", {});
      const std::size_t at = 8 + 25; // after the signature and IHDR (12 + 13 bytes)
      for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<std::uint8_t>(length >> (24 - 8 * i));
      const auto name = std::string(type) + std::to_string(length) + ".png";
      test::write_bytes(dir.file(name), bytes);
      expect_png_error(dir.file(name), "declares " + std::to_string(length) + " bytes");
    }
  }
}

// Empty IDAT chunks are legal; stb_image would copy one into its still-null buffer (undefined
// behaviour under UBSan, a fuzzer finding). They are dropped before decoding: same pixels.
TEST(Png, EmptyIdatChunksDecodeLikeTheFileWithoutThem) {
  TempDir dir;
  const Framebuffer image = test::random_image(16, 8, 11);
  write_png(image, dir.file("plain.png"));
  const Bytes plain = test::read_bytes(dir.file("plain.png"));
  Bytes with_empty(plain.begin(), plain.begin() + 33); // signature and IHDR
  test::put_chunk(with_empty, "IDAT", {});
  with_empty.insert(with_empty.end(), plain.begin() + 33, plain.end() - 12);
  test::put_chunk(with_empty, "IDAT", {});
  with_empty.insert(with_empty.end(), plain.end() - 12, plain.end()); // IEND
  test::write_bytes(dir.file("empty_idat.png"), with_empty);
  const Framebuffer a = read_png(dir.file("plain.png"));
  const Framebuffer b = read_png(dir.file("empty_idat.png"));
  ASSERT_EQ(a.width(), b.width());
  ASSERT_EQ(a.height(), b.height());
  for (std::size_t i = 0; i < a.pixels().size(); ++i) EXPECT_EQ(a.pixels()[i], b.pixels()[i]) << i;
}

TEST(Png, WriteToMissingFolderThrowsNamingThePath) {
  TempDir dir;
  const auto path = dir.file("no_such_folder") / "out.png";
  try {
    write_png(Framebuffer(2, 2), path);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_folder"), std::string::npos) << e.what();
  }
}

// --- OpenEXR -------------------------------------------------------------------------------------

/// One channel for write_openexr: a name, the stored type, one value per pixel (row-major).
struct ChannelData {
  std::string name;
  Imf::PixelType type = Imf::FLOAT;
  std::vector<float> values;
};

/// The value a file of this pixel type holds for v: HALF rounds to nearest, UINT truncates.
float stored(Imf::PixelType type, float v) {
  if (type == Imf::HALF) return static_cast<float>(Imath::half(v));
  if (type == Imf::UINT) return static_cast<float>(static_cast<std::uint32_t>(v));
  return v;
}

struct OpenExrLayout {
  Imf::Compression compression = Imf::ZIP_COMPRESSION;
  Imath::V2i origin{0, 0};                   ///< data window minimum
  std::optional<Imf::TileDescription> tiles; ///< tiled when set (every level written)
};

/// Writes a file with the OpenEXR library itself (not through Specula), so the reader is checked
/// against the real producer in every compression, pixel type and layout.
void write_openexr(const std::filesystem::path& path, int width, int height,
                   const std::vector<ChannelData>& channels, const OpenExrLayout& layout = {}) {
  Imf::Header header(width, height);
  header.dataWindow() =
      Imath::Box2i(layout.origin, layout.origin + Imath::V2i(width - 1, height - 1));
  header.compression() = layout.compression;
  std::vector<std::vector<char>> storage;
  Imf::FrameBuffer slices;
  for (const ChannelData& channel : channels) {
    const std::size_t size = channel.type == Imf::HALF ? 2 : 4;
    std::vector<char>& bytes = storage.emplace_back(size * channel.values.size());
    for (std::size_t i = 0; i < channel.values.size(); ++i) {
      const float v = channel.values[i];
      if (channel.type == Imf::HALF) {
        const Imath::half h(v);
        std::memcpy(&bytes[2 * i], &h, 2);
      } else if (channel.type == Imf::UINT) {
        const auto u = static_cast<std::uint32_t>(v);
        std::memcpy(&bytes[4 * i], &u, 4);
      } else {
        std::memcpy(&bytes[4 * i], &v, 4);
      }
    }
    header.channels().insert(channel.name, Imf::Channel(channel.type));
    slices.insert(channel.name,
                  Imf::Slice::Make(channel.type, bytes.data(), layout.origin, width, height, size,
                                   size * static_cast<std::size_t>(width)));
  }
  if (layout.tiles) {
    header.setTileDescription(*layout.tiles);
    Imf::TiledOutputFile file(path.c_str(), header);
    file.setFrameBuffer(slices);
    // Lower levels take their pixels from the top-left of the same buffer: valid, if not a
    // real mip map; the reader only reads level 0.
    for (int ly = 0; ly < file.numYLevels(); ++ly) {
      for (int lx = 0; lx < file.numXLevels(); ++lx) {
        if (!file.isValidLevel(lx, ly)) continue;
        file.writeTiles(0, file.numXTiles(lx) - 1, 0, file.numYTiles(ly) - 1, lx, ly);
      }
    }
  } else {
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(slices);
    file.writePixels(height);
  }
}

/// R, G, B channels of one type with the image's values (converted to that type on writing).
std::vector<ChannelData> rgb_channels(const Framebuffer& image, Imf::PixelType type) {
  std::vector<ChannelData> channels = {{"R", type, {}}, {"G", type, {}}, {"B", type, {}}};
  for (std::size_t c = 0; c < 3; ++c) {
    for (const vec3& p : image.pixels()) channels[c].values.push_back(p[static_cast<int>(c)]);
  }
  return channels;
}

Framebuffer stored_image(const Framebuffer& image, Imf::PixelType type) {
  Framebuffer out = image;
  for (vec3& p : out.pixels()) p = vec3(stored(type, p.r), stored(type, p.g), stored(type, p.b));
  return out;
}

/// A smooth image (lossy codecs are made for such content, not for noise), positive values.
Framebuffer smooth_image(std::uint32_t width, std::uint32_t height) {
  Framebuffer image(width, height);
  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      const float fx = static_cast<float>(x);
      const float fy = static_cast<float>(y);
      image.at(x, y) = vec3(0.5f + 0.4f * std::sin(0.2f * fx) * std::cos(0.15f * fy),
                            0.25f + 0.002f * fx * fy, 2.0f + std::cos(0.1f * (fx + fy)));
    }
  }
  return image;
}

/// Largest |a − b| / max(|b|, floor) over every channel of every pixel.
float worst_relative_error(const Framebuffer& a, const Framebuffer& b, float floor = 1e-3f) {
  float worst = 0.0f;
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const float expected = b.pixels()[i][c];
      const float error = std::abs(a.pixels()[i][c] - expected);
      worst = std::max(worst, error / std::max(std::abs(expected), floor));
    }
  }
  return worst;
}

/// For file names and messages (OpenEXR 3.1 has no name lookup).
std::string compression_name(Imf::Compression compression) {
  constexpr std::array<const char*, 10> kNames = {"none",  "rle", "zips", "zip",  "piz",
                                                  "pxr24", "b44", "b44a", "dwaa", "dwab"};
  return kNames.at(static_cast<std::size_t>(compression));
}

/// Bit-identical pixels (unlike ==, tells −0 from +0), with the first difference reported.
::testing::AssertionResult same_bits(const Framebuffer& a, const Framebuffer& b) {
  if (a.width() != b.width() || a.height() != b.height()) {
    return ::testing::AssertionFailure() << "sizes differ";
  }
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    if (std::memcmp(&a.pixels()[i], &b.pixels()[i], sizeof(vec3)) != 0) {
      return ::testing::AssertionFailure()
             << "pixel " << i << ": (" << a.pixels()[i].r << ", " << a.pixels()[i].g << ", "
             << a.pixels()[i].b << ") vs (" << b.pixels()[i].r << ", " << b.pixels()[i].g << ", "
             << b.pixels()[i].b << ")";
    }
  }
  return ::testing::AssertionSuccess();
}

TEST(Exr, RoundTripIsBitExact) {
  TempDir dir;
  // Noise, which ZIP cannot shrink (such blocks are stored raw), and a smooth image, which it
  // does shrink, so both paths through the codec are covered.
  for (Framebuffer original :
       {test::random_image(19, 11, 99, -100.0f, 100.0f), smooth_image(64, 40)}) {
    // Values that a careless encoder loses: signed zero, subnormals, extremes.
    original.at(0, 0) = vec3(-0.0f, std::numeric_limits<float>::denorm_min(), 1e-40f);
    original.at(1, 0) = vec3(std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(),
                             std::numeric_limits<float>::min());
    const auto path = dir.file("round" + std::to_string(original.width()) + ".exr");
    write_exr(original, path);
    EXPECT_TRUE(same_bits(read_exr(path), original)) << path;
  }
  // Smaller than its raw floats alone: blocks were compressed, not stored raw.
  EXPECT_LT(std::filesystem::file_size(dir.file("round64.exr")),
            std::uintmax_t{64} * 40 * sizeof(vec3));
}

TEST(Exr, WriterStoresZipCompressedFloatRgb) {
  TempDir dir;
  // 40 rows: more than one 16-line ZIP block, the last one partial.
  write_exr(test::random_image(7, 40, 5), dir.file("zip.exr"));
  Imf::InputFile file(dir.file("zip.exr").c_str());
  const Imf::Header& header = file.header();
  EXPECT_EQ(header.compression(), Imf::ZIP_COMPRESSION);
  EXPECT_EQ(header.dataWindow(), Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(6, 39)));
  EXPECT_EQ(header.displayWindow(), header.dataWindow());
  std::vector<std::string> names;
  for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
    names.emplace_back(it.name());
    EXPECT_EQ(it.channel().type, Imf::FLOAT) << it.name();
  }
  EXPECT_EQ(names, (std::vector<std::string>{"B", "G", "R"}));
  EXPECT_TRUE(file.isComplete());
}

TEST(Exr, WriterRefusesNonFiniteValuesAndWritesNothing) {
  TempDir dir;
  Framebuffer image(3, 3, vec3(0.5f));
  image.at(2, 1).g = std::numeric_limits<float>::quiet_NaN();
  try {
    write_exr(image, dir.file("nan.exr"));
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nan.exr"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("(2, 1)"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir.file("nan.exr")));
  image.at(2, 1).g = std::numeric_limits<float>::infinity();
  EXPECT_THROW(write_exr(image, dir.file("inf.exr")), Error);
}

TEST(Exr, WriteErrorsNameThePath) {
  TempDir dir;
  const Framebuffer image = test::random_image(64, 64, 8);
  const auto expect_write_error = [&](const std::filesystem::path& path) {
    try {
      write_exr(image, path);
      ADD_FAILURE() << "no error for " << path;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("cannot write EXR"), std::string::npos) << e.what();
    }
  };
  expect_write_error(dir.file("no_such_folder") / "out.exr");
  std::filesystem::create_directory(dir.file("folder.exr"));
  expect_write_error(dir.file("folder.exr"));
  // A device that accepts the open and fails every write: the error must not be lost in a
  // buffer or a destructor.
  if (std::filesystem::exists("/dev/full")) expect_write_error("/dev/full");
}

TEST(Exr, ReadsEveryLosslessCompressionAndPixelTypeExactly) {
  TempDir dir;
  // 37 x 70: odd width, and more rows than the largest lossless block (32 lines for PIZ), with
  // a partial last block. The data window is offset: its origin is dropped on read.
  const Framebuffer random = test::random_image(37, 70, 21, -300.0f, 300.0f);
  Framebuffer counts(37, 70); // UINT: whole numbers, exact in a float below 2^24
  std::mt19937 rng(22);
  std::uniform_int_distribution<std::uint32_t> count(0, (1u << 24) - 1);
  for (vec3& p : counts.pixels()) {
    p = vec3(static_cast<float>(count(rng)), static_cast<float>(count(rng)), 0.0f);
  }
  OpenExrLayout layout;
  layout.origin = Imath::V2i(-4, 9);
  for (const Imf::Compression compression :
       {Imf::NO_COMPRESSION, Imf::RLE_COMPRESSION, Imf::ZIPS_COMPRESSION, Imf::ZIP_COMPRESSION,
        Imf::PIZ_COMPRESSION}) {
    layout.compression = compression;
    for (const Imf::PixelType type : {Imf::FLOAT, Imf::HALF, Imf::UINT}) {
      const Framebuffer& source = type == Imf::UINT ? counts : random;
      const auto name = compression_name(compression) + std::to_string(type) + ".exr";
      write_openexr(dir.file(name), 37, 70, rgb_channels(source, type), layout);
      EXPECT_TRUE(same_bits(read_exr(dir.file(name)), stored_image(source, type))) << name;
    }
  }
}

TEST(Exr, ReadsLossyCompressionsWithinTheirPrecision) {
  TempDir dir;
  const Framebuffer image = smooth_image(45, 67);
  OpenExrLayout layout;
  // PXR24 rounds FLOAT to 24 bits (8 exponent, 15 mantissa bits): relative error at most 2^-16.
  // HALF channels it stores exactly (after zip).
  layout.compression = Imf::PXR24_COMPRESSION;
  write_openexr(dir.file("pxr24f.exr"), 45, 67, rgb_channels(image, Imf::FLOAT), layout);
  EXPECT_LE(worst_relative_error(read_exr(dir.file("pxr24f.exr")), image), std::ldexp(1.0f, -16));
  write_openexr(dir.file("pxr24h.exr"), 45, 67, rgb_channels(image, Imf::HALF), layout);
  EXPECT_TRUE(same_bits(read_exr(dir.file("pxr24h.exr")), stored_image(image, Imf::HALF)));

  // B44 and B44A quantise 4x4 blocks of HALF samples and store FLOAT channels as they are. DWAA
  // and DWAB quantise the DCT of R, G and B in 8x8 blocks (default level 45, "visually
  // lossless"), FLOAT channels too. The bounds are the worst errors measured on this image (1.4%
  // for B44, 2.3% for DWA) with some margin: enough to tell the right image from one with
  // swapped channels or pixels shifted by one (R changes by up to 16% between neighbours).
  for (const Imf::Compression compression : {Imf::B44_COMPRESSION, Imf::B44A_COMPRESSION,
                                             Imf::DWAA_COMPRESSION, Imf::DWAB_COMPRESSION}) {
    layout.compression = compression;
    const bool b44 = compression == Imf::B44_COMPRESSION || compression == Imf::B44A_COMPRESSION;
    for (const Imf::PixelType type : {Imf::HALF, Imf::FLOAT}) {
      const auto name = compression_name(compression) + std::to_string(type) + ".exr";
      write_openexr(dir.file(name), 45, 67, rgb_channels(image, type), layout);
      const Framebuffer back = read_exr(dir.file(name));
      if (b44 && type == Imf::FLOAT) {
        EXPECT_TRUE(same_bits(back, image)) << name;
      } else {
        ASSERT_EQ(back.width(), 45u) << name;
        ASSERT_EQ(back.height(), 67u) << name;
        EXPECT_LE(worst_relative_error(back, image), b44 ? 0.03f : 0.05f) << name;
      }
    }
  }
}

TEST(Exr, ReadsTiledFilesOneLevelAndMipMapped) {
  TempDir dir;
  const Framebuffer image = test::random_image(37, 23, 31, -5.0f, 5.0f);
  OpenExrLayout layout;
  layout.origin = Imath::V2i(3, -2);
  layout.compression = Imf::ZIPS_COMPRESSION;
  layout.tiles = Imf::TileDescription(16, 8, Imf::ONE_LEVEL);
  write_openexr(dir.file("tiled.exr"), 37, 23, rgb_channels(image, Imf::FLOAT), layout);
  EXPECT_TRUE(same_bits(read_exr(dir.file("tiled.exr")), image));
  // Tiles larger than the image, PIZ, HALF, and a mip map of which level 0 is read.
  layout.compression = Imf::PIZ_COMPRESSION;
  layout.tiles = Imf::TileDescription(64, 64, Imf::MIPMAP_LEVELS, Imf::ROUND_UP);
  write_openexr(dir.file("mipmap.exr"), 37, 23, rgb_channels(image, Imf::HALF), layout);
  EXPECT_TRUE(same_bits(read_exr(dir.file("mipmap.exr")), stored_image(image, Imf::HALF)));
}

TEST(Exr, ReadsLuminanceOnlyAsGrayAndRefusesChroma) {
  TempDir dir;
  const Framebuffer image = test::random_image(9, 5, 41);
  std::vector<ChannelData> luminance = {{"Y", Imf::HALF, {}}};
  for (const vec3& p : image.pixels()) luminance[0].values.push_back(p.g);
  write_openexr(dir.file("y.exr"), 9, 5, luminance);
  const Framebuffer gray = read_exr(dir.file("y.exr"));
  ASSERT_EQ(gray.width(), 9u);
  for (std::size_t i = 0; i < image.pixel_count(); ++i) {
    EXPECT_EQ(gray.pixels()[i], vec3(stored(Imf::HALF, image.pixels()[i].g))) << i;
  }
  // Luminance-chroma images (Y, RY, BY, as RgbaOutputFile writes them) need a colour
  // conversion the reader does not make.
  std::vector<ChannelData> chroma = luminance;
  chroma.push_back({"RY", Imf::HALF, luminance[0].values});
  chroma.push_back({"BY", Imf::HALF, luminance[0].values});
  write_openexr(dir.file("ryby.exr"), 9, 5, chroma);
  expect_exr_error(dir.file("ryby.exr"), "unsupported EXR: no R, G, B channels");
  expect_exr_error(dir.file("ryby.exr"), "found: BY RY Y");
}

// The chunk check decodes through OpenEXRCore, whose fast unpackers for 3 and 4 interleaved HALF
// channels once received a luminance image's Y among unread channels (the fuzzer's B, G, Y): they
// wrote all three channels, two of them to null. Every count and position of the extra channels,
// of both pixel types, each compression that takes Core's unpack path.
TEST(Exr, ReadsLuminanceBesideUnreadChannelsInAnyPosition) {
  TempDir dir;
  const Framebuffer image = test::random_image(7, 20, 43);
  const std::vector<std::vector<std::string>> layouts = {
      {"B", "G", "Y"}, {"A", "Y", "Z"}, {"Y", "Z", "ZZ"}, {"A", "B", "G", "Y"}, {"Y", "Z"}};
  int n = 0;
  for (const auto& names : layouts) {
    for (const Imf::PixelType type : {Imf::HALF, Imf::FLOAT}) {
      for (const Imf::Compression compression : {Imf::NO_COMPRESSION, Imf::ZIP_COMPRESSION}) {
        std::vector<ChannelData> channels;
        for (const std::string& name : names) {
          ChannelData& channel = channels.emplace_back(ChannelData{name, type, {}});
          for (const vec3& p : image.pixels()) channel.values.push_back(name == "Y" ? p.g : p.r);
        }
        const auto path = dir.file("y" + std::to_string(n++) + ".exr");
        write_openexr(path, 7, 20, channels, {compression, {0, 0}, {}});
        const Framebuffer gray = read_exr(path);
        ASSERT_EQ(gray.width(), 7u);
        ASSERT_EQ(gray.height(), 20u);
        for (std::size_t i = 0; i < image.pixel_count(); ++i) {
          ASSERT_EQ(gray.pixels()[i], vec3(stored(type, image.pixels()[i].g))) << path << " " << i;
        }
      }
    }
  }
}

TEST(Exr, MultiPartAndDeepFilesAreUnsupported) {
  TempDir dir;
  std::array<Imf::Header, 2> headers = {Imf::Header(2, 2), Imf::Header(2, 2)};
  std::vector<float> pixels(4, 0.5f);
  Imf::FrameBuffer slices;
  slices.insert("R", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(pixels.data()), 4, 8));
  for (std::size_t i = 0; i < headers.size(); ++i) {
    headers[i].setName("part" + std::to_string(i));
    headers[i].setType(Imf::SCANLINEIMAGE);
    headers[i].channels().insert("R", Imf::Channel(Imf::FLOAT));
  }
  {
    Imf::MultiPartOutputFile file(dir.file("multi.exr").c_str(), headers.data(), 2);
    for (int part = 0; part < 2; ++part) {
      Imf::OutputPart out(file, part);
      out.setFrameBuffer(slices);
      out.writePixels(2);
    }
  }
  expect_exr_error(dir.file("multi.exr"), "unsupported EXR: multi-part");

  // One sample per pixel of a 2x2 deep scan-line image.
  Imf::Header deep(2, 2);
  deep.setType(Imf::DEEPSCANLINE);
  deep.compression() = Imf::ZIPS_COMPRESSION;
  deep.channels().insert("R", Imf::Channel(Imf::FLOAT));
  std::vector<std::uint32_t> counts(4, 1);
  std::vector<float*> samples;
  for (float& v : pixels) samples.push_back(&v);
  Imf::DeepFrameBuffer deep_slices;
  deep_slices.insertSampleCountSlice(
      Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()), 4, 8));
  deep_slices.insert("R", Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(samples.data()),
                                         sizeof(float*), 2 * sizeof(float*), sizeof(float)));
  {
    Imf::DeepScanLineOutputFile file(dir.file("deep.exr").c_str(), deep);
    file.setFrameBuffer(deep_slices);
    file.writePixels(2);
  }
  expect_exr_error(dir.file("deep.exr"), "unsupported EXR: deep data");
}

/// A hand-made scan-line EXR, built here independently of the library and of the writer.
struct ExrSpec {
  std::uint32_t version = 2;
  std::vector<std::pair<std::string, std::int32_t>> channels = {{"B", 2}, {"G", 2}, {"R", 2}};
  std::int32_t sampling = 1;
  std::uint8_t compression = 0;
  std::array<std::int32_t, 4> data_window = {0, 0, 1, 1};
  std::uint8_t line_order = 0; ///< 1: blocks stored bottom line first
  bool with_pixels = true;
  std::vector<std::string> omit;                    ///< required attributes left out
  std::vector<std::pair<std::string, Bytes>> extra; ///< more attributes: name, "type\0value"
};

/// raw(x, y, channel): the sample's bits (float bits for FLOAT, the low 16 bits for HALF).
using RawSample = std::function<std::uint32_t(int, int, const std::string&)>;

struct LeBytes {
  Bytes bytes;
  void u8(std::uint32_t v) { bytes.push_back(static_cast<std::uint8_t>(v)); }
  void u16(std::uint32_t v) { u8(v), u8(v >> 8); }
  void u32(std::uint32_t v) { u16(v), u16(v >> 16); }
  void u64(std::uint64_t v) {
    u32(static_cast<std::uint32_t>(v)), u32(static_cast<std::uint32_t>(v >> 32));
  }
  void str(const std::string& s) {
    bytes.insert(bytes.end(), s.begin(), s.end());
    u8(0);
  }
  void attribute(const std::string& name, const std::string& type, const Bytes& value) {
    str(name);
    str(type);
    u32(static_cast<std::uint32_t>(value.size()));
    bytes.insert(bytes.end(), value.begin(), value.end());
  }
};

Bytes build_exr(const ExrSpec& spec, const RawSample& raw) {
  LeBytes out;
  for (std::uint8_t b : {0x76, 0x2F, 0x31, 0x01}) out.u8(b);
  out.u32(spec.version);
  const auto put = [&](const std::string& name, const std::string& type, const Bytes& value) {
    if (std::find(spec.omit.begin(), spec.omit.end(), name) == spec.omit.end()) {
      out.attribute(name, type, value);
    }
  };
  LeBytes channels;
  for (const auto& [name, type] : spec.channels) {
    channels.str(name);
    channels.u32(static_cast<std::uint32_t>(type));
    channels.u32(0); // pLinear + reserved
    channels.u32(static_cast<std::uint32_t>(spec.sampling));
    channels.u32(static_cast<std::uint32_t>(spec.sampling));
  }
  channels.u8(0);
  put("channels", "chlist", channels.bytes);
  put("compression", "compression", {spec.compression});
  LeBytes window;
  for (std::int32_t v : spec.data_window) window.u32(static_cast<std::uint32_t>(v));
  put("dataWindow", "box2i", window.bytes);
  put("displayWindow", "box2i", window.bytes);
  put("lineOrder", "lineOrder", {spec.line_order});
  LeBytes one;
  one.u32(std::bit_cast<std::uint32_t>(1.0f));
  put("pixelAspectRatio", "float", one.bytes);
  put("owner", "string", {'t', 'e', 's', 't'}); // an attribute Specula does not use
  put("screenWindowCenter", "v2f", Bytes(8, 0));
  put("screenWindowWidth", "float", one.bytes);
  for (const auto& [name, type_and_value] : spec.extra) {
    const auto zero = std::find(type_and_value.begin(), type_and_value.end(), 0);
    out.attribute(name, std::string(type_and_value.begin(), zero),
                  Bytes(zero + 1, type_and_value.end()));
  }
  out.u8(0);
  if (!spec.with_pixels) return out.bytes;

  const auto [x_min, y_min, x_max, y_max] = spec.data_window;
  const int height = y_max - y_min + 1;
  std::vector<Bytes> blocks;
  for (int y = y_min; y <= y_max; ++y) {
    LeBytes data;
    for (const auto& [name, type] : spec.channels) {
      for (int x = x_min; x <= x_max; ++x) {
        type == 1 ? data.u16(raw(x, y, name)) : data.u32(raw(x, y, name));
      }
    }
    LeBytes block;
    block.u32(static_cast<std::uint32_t>(y));
    block.u32(static_cast<std::uint32_t>(data.bytes.size()));
    block.bytes.insert(block.bytes.end(), data.bytes.begin(), data.bytes.end());
    blocks.push_back(block.bytes);
  }
  // Offsets are indexed by line; the blocks themselves are stored in line order.
  std::vector<std::uint64_t> offsets(static_cast<std::size_t>(height));
  std::uint64_t position = out.bytes.size() + 8 * offsets.size();
  for (int k = 0; k < height; ++k) {
    const int line = spec.line_order == 1 ? height - 1 - k : k;
    offsets[static_cast<std::size_t>(line)] = position;
    position += blocks[static_cast<std::size_t>(line)].size();
  }
  for (std::uint64_t o : offsets) out.u64(o);
  for (int k = 0; k < height; ++k) {
    const int line = spec.line_order == 1 ? height - 1 - k : k;
    const Bytes& b = blocks[static_cast<std::size_t>(line)];
    out.bytes.insert(out.bytes.end(), b.begin(), b.end());
  }
  return out.bytes;
}

/// Float samples encoding their own position: R = x + 10y, G = −(x + 10y), B = 0.5.
std::uint32_t position_sample(int x, int y, const std::string& channel) {
  const float v = static_cast<float>(x + 10 * y);
  if (channel == "R") return std::bit_cast<std::uint32_t>(v);
  if (channel == "G") return std::bit_cast<std::uint32_t>(-v);
  if (channel == "B") return std::bit_cast<std::uint32_t>(0.5f);
  return std::bit_cast<std::uint32_t>(123.0f);
}

TEST(Exr, ReadsHandMadeFilesAnyLineOrderExtraChannelsOffsetWindow) {
  TempDir dir;
  ExrSpec spec;
  spec.channels = {{"A", 2}, {"B", 2}, {"G", 2}, {"R", 2}, {"Z", 1}};
  spec.data_window = {5, -3, 8, -1}; // 4 x 3 pixels, origin dropped on read
  for (std::uint8_t order : {0, 1}) {
    spec.line_order = order;
    const auto path = dir.file("hand" + std::to_string(order) + ".exr");
    test::write_bytes(path, build_exr(spec, position_sample));
    const Framebuffer image = read_exr(path);
    ASSERT_EQ(image.width(), 4u);
    ASSERT_EQ(image.height(), 3u);
    for (int y = 0; y < 3; ++y) {
      for (int x = 0; x < 4; ++x) {
        const float v = static_cast<float>((x + 5) + 10 * (y - 3));
        EXPECT_EQ(image.at(static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y)),
                  vec3(v, -v, 0.5f));
      }
    }
  }
}

TEST(Exr, ReadsHalfChannelsExactly) {
  TempDir dir;
  ExrSpec spec;
  spec.channels = {{"B", 1}, {"G", 1}, {"R", 1}};
  spec.data_window = {0, 0, 2, 0};
  // Half bit patterns with known values: 1, 0.5, −2, the largest half, the smallest subnormal.
  const std::array<std::array<std::uint32_t, 3>, 3> halves = {{
      {0x3C00, 0x3800, 0xC000}, // R, G, B of pixel 0
      {0x7BFF, 0x0001, 0x8000},
      {0x3555, 0x0400, 0x03FF},
  }};
  const auto raw = [&](int x, int, const std::string& c) {
    return halves[static_cast<std::size_t>(x)][c == "R" ? 0 : c == "G" ? 1 : 2];
  };
  test::write_bytes(dir.file("half.exr"), build_exr(spec, raw));
  const Framebuffer image = read_exr(dir.file("half.exr"));
  EXPECT_EQ(image.at(0, 0), vec3(1.0f, 0.5f, -2.0f));
  EXPECT_EQ(image.at(1, 0), vec3(65504.0f, std::ldexp(1.0f, -24), -0.0f));
  EXPECT_TRUE(std::signbit(image.at(1, 0).b));
  // 0x3555 = 1 + 341/1024 · 2^-2 exponent form: (1024 + 341) · 2^-12; 0x0400 smallest normal.
  EXPECT_EQ(image.at(2, 0),
            vec3(1365.0f / 4096.0f, std::ldexp(1.0f, -14), 1023.0f * std::ldexp(1.0f, -24)));
}

TEST(Exr, ReadsAFileWrittenByTheOpenExrLibrary) {
  // HALF channels and attributes Specula does not know, from a real producer (see
  // tests/data/image/README.md): every sample is exactly (x + 8y) / 8.
  const Framebuffer image =
      read_exr(std::filesystem::path(SPECULA_TEST_DATA_DIR) / "image" / "openexr_half_ramp.exr");
  ASSERT_EQ(image.width(), 8u);
  ASSERT_EQ(image.height(), 4u);
  for (std::uint32_t y = 0; y < 4; ++y) {
    for (std::uint32_t x = 0; x < 8; ++x) {
      EXPECT_EQ(image.at(x, y), vec3(static_cast<float>(x + 8 * y) / 8.0f)) << x << ", " << y;
    }
  }
}

TEST(Exr, BadFilesThrowErrorsNamingTheFile) {
  TempDir dir;
  expect_exr_error(dir.file("missing.exr"), "not found");
  test::write_bytes(dir.file("empty.exr"), {});
  expect_exr_error(dir.file("empty.exr"), "empty");
  std::filesystem::create_directory(dir.file("folder.exr"));
  expect_exr_error(dir.file("folder.exr"), "directory");
  write_png(Framebuffer(2, 2), dir.file("png_inside.exr"));
  expect_exr_error(dir.file("png_inside.exr"), "magic");
  test::write_bytes(dir.file("three.exr"), Bytes{0x76, 0x2F, 0x31});
  expect_exr_error(dir.file("three.exr"), "magic");
  test::write_bytes(dir.file("garbage.exr"), [] {
    Bytes garbage = {0x76, 0x2F, 0x31, 0x01, 2, 0, 0, 0};
    std::mt19937 rng(5);
    for (int i = 0; i < 500; ++i) garbage.push_back(static_cast<std::uint8_t>(rng()));
    return garbage;
  }());
  expect_exr_error(dir.file("garbage.exr"));

  // Truncations of a valid ZIP file in every region: version, header, offset table, data. The
  // image is smooth so that ZIP does compress it (a chunk that would not shrink is stored raw,
  // and garbage in raw floats is not detectable).
  write_exr(smooth_image(8, 40), dir.file("valid.exr"));
  const Bytes valid = test::read_bytes(dir.file("valid.exr"));
  for (std::size_t size : {std::size_t{6}, std::size_t{40}, std::size_t{300}, std::size_t{340},
                           valid.size() / 2, valid.size() - 1}) {
    const auto name = "cut" + std::to_string(size) + ".exr";
    test::write_bytes(dir.file(name),
                      Bytes(valid.begin(), valid.begin() + static_cast<long>(size)));
    expect_exr_error(dir.file(name));
  }
  // The same file with its compressed data overwritten by garbage.
  Bytes scrambled = valid;
  std::fill(scrambled.end() - 200, scrambled.end(), std::uint8_t{0xAB});
  test::write_bytes(dir.file("scrambled.exr"), scrambled);
  expect_exr_error(dir.file("scrambled.exr"));

  // A header declaring 10^9 x 10^9 pixels, with nothing after it.
  ExrSpec huge;
  huge.data_window = {0, 0, 999'999'999, 999'999'999};
  huge.with_pixels = false;
  test::write_bytes(dir.file("huge.exr"), build_exr(huge, position_sample));
  expect_exr_error(dir.file("huge.exr"), "1000000000x1000000000");
  // Inverted window, and the widest window int32 allows (overflow bait).
  huge.data_window = {10, 0, 0, 0};
  test::write_bytes(dir.file("inverted.exr"), build_exr(huge, position_sample));
  expect_exr_error(dir.file("inverted.exr"), "data window");
  huge.data_window = {std::numeric_limits<std::int32_t>::min(), 0,
                      std::numeric_limits<std::int32_t>::max(), 0};
  test::write_bytes(dir.file("widest.exr"), build_exr(huge, position_sample));
  expect_exr_error(dir.file("widest.exr"), "4294967296x1");
  // The largest allowed window in 1x1 tiles: 2^28 tiles, whose offset table alone (2 GiB)
  // cannot fit in the file.
  ExrSpec tiny_tiles;
  tiny_tiles.version = 2 | 0x200;
  tiny_tiles.data_window = {0, 0, 16383, 16383};
  tiny_tiles.with_pixels = false;
  tiny_tiles.extra = {
      {"tiles", {'t', 'i', 'l', 'e', 'd', 'e', 's', 'c', 0, 1, 0, 0, 0, 1, 0, 0, 0, 0}}};
  test::write_bytes(dir.file("tiny_tiles.exr"), build_exr(tiny_tiles, position_sample));
  expect_exr_error(dir.file("tiny_tiles.exr"), "too big for file size");
  // A 2 GiB string attribute in a 200-byte file: refused before the library allocates it.
  ExrSpec forged;
  forged.with_pixels = false;
  forged.extra = {{"comments", {'s', 't', 'r', 'i', 'n', 'g', 0}}};
  Bytes long_string = build_exr(forged, position_sample);
  const std::size_t size_at = long_string.size() - 5; // the last attribute's size, then the 0
  for (std::size_t i = 0; i < 4; ++i) long_string[size_at + i] = i < 3 ? 0xFF : 0x7F;
  test::write_bytes(dir.file("long_string.exr"), long_string);
  expect_exr_error(dir.file("long_string.exr"), "'comments' declares 2147483647 bytes");
  // A required attribute of another type (a flipped byte in "chlist"): OpenEXR 3.1's
  // Header::sanityCheck crashes on such a header unless readFrom refuses it first.
  ExrSpec mistyped;
  mistyped.omit = {"channels"};
  mistyped.extra = {{"channels", {'c', 'h', 'l', 0xEC, 's', 't', 0, 'R', 0, 2, 0, 0, 0,
                                  0,   0,   0,   0,    1,   0,   0, 0,   1, 0, 0, 0, 0}}};
  test::write_bytes(dir.file("mistyped.exr"), build_exr(mistyped, position_sample));
  expect_exr_error(dir.file("mistyped.exr"), "channels");
  // Channels out of order: the library would sort them and give R the samples stored as B (and
  // OpenEXRCore 3.1 crashes on some such files).
  ExrSpec unsorted;
  unsorted.channels = {{"R", 2}, {"G", 2}, {"B", 2}};
  test::write_bytes(dir.file("unsorted.exr"), build_exr(unsorted, position_sample));
  expect_exr_error(dir.file("unsorted.exr"), "channel list not sorted by name ('R' before 'G')");
  unsorted.channels = {{"B", 2}, {"G", 2}, {"G", 2}, {"R", 2}};
  test::write_bytes(dir.file("twice.exr"), build_exr(unsorted, position_sample));
  expect_exr_error(dir.file("twice.exr"), "not sorted");
  // Required attributes missing: the library would use defaults (a 64x64 window) instead.
  for (const char* attribute : {"channels", "compression", "dataWindow", "lineOrder"}) {
    ExrSpec incomplete;
    incomplete.omit = {attribute};
    const auto name = std::string("no_") + attribute + ".exr";
    test::write_bytes(dir.file(name), build_exr(incomplete, position_sample));
    expect_exr_error(dir.file(name), std::string("no ") + attribute + " attribute");
  }

  // NaN and infinity in pixel data (FLOAT and HALF).
  ExrSpec small;
  test::write_bytes(dir.file("nan.exr"), build_exr(small, [](int x, int y, const std::string& c) {
                      return x == 1 && y == 1 && c == "G"
                                 ? std::bit_cast<std::uint32_t>(
                                       std::numeric_limits<float>::quiet_NaN())
                                 : std::bit_cast<std::uint32_t>(0.25f);
                    }));
  expect_exr_error(dir.file("nan.exr"), "NaN");
  expect_exr_error(dir.file("nan.exr"), "(1, 1) channel G");
  ExrSpec half = small;
  half.channels = {{"B", 1}, {"G", 1}, {"R", 1}};
  test::write_bytes(dir.file("inf.exr"), build_exr(half, [](int x, int, const std::string&) {
                      return x == 0 ? 0x7C00u : 0x3C00u; // +Inf
                    }));
  expect_exr_error(dir.file("inf.exr"), "infinite");
  // ... and in a compressed file written by the library.
  Framebuffer with_nan = test::random_image(20, 20, 6);
  with_nan.at(13, 17).b = std::numeric_limits<float>::quiet_NaN();
  write_openexr(dir.file("nan_piz.exr"), 20, 20, rgb_channels(with_nan, Imf::HALF),
                {Imf::PIZ_COMPRESSION, {0, 0}, std::nullopt});
  expect_exr_error(dir.file("nan_piz.exr"), "(13, 17) channel B is NaN");
}

/// Where the value of the header attribute `name` of type `type` starts in an EXR file.
std::size_t attribute_value_at(const Bytes& file, const std::string& name,
                               const std::string& type) {
  const std::string key = name + '\0' + type + '\0';
  const auto found = std::search(file.begin(), file.end(), key.begin(), key.end());
  EXPECT_NE(found, file.end()) << name;
  return static_cast<std::size_t>(found - file.begin()) + key.size() + 4; // after the size field
}

void put_le32(Bytes& file, std::size_t at, std::uint32_t v) {
  for (std::size_t i = 0; i < 4; ++i) file[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// OpenEXR reads fixed-size types at their own size, a channel list until its empty name, and
// sizes string-vector strings and preview pixels from numbers inside the value — whatever size
// the attribute declares. A value framed otherwise makes the library's parse part from the
// framing (a fuzzer finding: a 379-byte file asked for 1.8 GB), so it is refused first.
TEST(Exr, AttributeValuesTheLibraryWouldReadOtherwiseAreRefused) {
  TempDir dir;
  const auto value = [](const std::string& type, const Bytes& bytes) {
    Bytes out(type.begin(), type.end());
    out.push_back(0);
    out.insert(out.end(), bytes.begin(), bytes.end());
    return out;
  };
  LeBytes long_string;
  long_string.u32(0x40000000); // a string of 1 GiB announced inside an 8-byte value
  long_string.u32(0);
  LeBytes preview;
  preview.u32(100000);
  preview.u32(100000);
  LeBytes list; // one channel, its terminator, then 20 bytes the library would take for more
  list.str("Z");
  for (int i = 0; i < 4; ++i) list.u32(0);
  list.u8(0);
  for (int i = 0; i < 5; ++i) list.u32(7);
  LeBytes unterminated; // one channel, then a name that runs to the value's end (no terminator)
  unterminated.str("Z");
  for (const std::uint32_t v : {2U, 0U, 1U, 1U}) unterminated.u32(v);
  unterminated.u8(5);
  const std::vector<std::pair<std::string, Bytes>> cases = {
      {"declares", value("float", Bytes(8, 0))},
      {"declares", value("box2i", Bytes(4, 0))},
      {"declares", value("compression", Bytes(2, 0))},
      {"string longer", value("stringvector", long_string.bytes)},
      {"pixels", value("preview", preview.bytes)},
      {"channel list does not end", value("chlist", list.bytes)},
      {"channel list does not end", value("chlist", unterminated.bytes)},
  };
  int index = 0;
  for (const auto& [needle, type_and_value] : cases) {
    ExrSpec spec;
    spec.extra = {{"extra", type_and_value}};
    const auto name = "attribute" + std::to_string(index++) + ".exr";
    test::write_bytes(dir.file(name), build_exr(spec, position_sample));
    expect_exr_error(dir.file(name), needle);
  }
  // The same attributes framed as the library reads them load.
  LeBytes good_list;
  good_list.str("Z");
  for (const std::uint32_t v : {2U, 0U, 1U, 1U}) good_list.u32(v); // float, pLinear, sampling
  good_list.u8(0);
  LeBytes good_strings;
  good_strings.u32(2);
  good_strings.u8('a');
  good_strings.u8('b');
  ExrSpec spec;
  spec.extra = {{"a", value("float", Bytes(4, 0))},
                {"b", value("stringvector", good_strings.bytes)},
                {"c", value("chlist", good_list.bytes)}};
  test::write_bytes(dir.file("good.exr"), build_exr(spec, position_sample));
  EXPECT_NO_THROW((void)read_exr(dir.file("good.exr")));
}

TEST(Exr, ChunksThatDecompressShortAreRefused) {
  // Found by fuzzing: the OpenEXR 3.1 C++ reader does not check that a chunk decompresses to
  // the size the header implies, and fills the rest of the image from uninitialised memory
  // without an error. A header made to disagree with valid chunks must be refused.
  TempDir dir;
  const Framebuffer image = smooth_image(24, 20);
  for (const Imf::Compression compression :
       {Imf::RLE_COMPRESSION, Imf::ZIPS_COMPRESSION, Imf::ZIP_COMPRESSION, Imf::PIZ_COMPRESSION}) {
    write_openexr(dir.file("valid.exr"), 24, 20, rgb_channels(image, Imf::HALF),
                  {compression, {0, 0}, std::nullopt});
    Bytes wide = test::read_bytes(dir.file("valid.exr"));
    put_le32(wide, attribute_value_at(wide, "dataWindow", "box2i") + 8, 159); // xMax 23 -> 159
    const auto name = "wide_" + compression_name(compression) + ".exr";
    test::write_bytes(dir.file(name), wide);
    expect_exr_error(dir.file(name), "corrupt EXR");
  }
  // Tiles of 8x8 relabelled 8x4616: one row of tiles, whose first chunks now seem short.
  write_openexr(dir.file("tiled.exr"), 24, 20, rgb_channels(image, Imf::FLOAT),
                {Imf::ZIP_COMPRESSION, {0, 0}, Imf::TileDescription(8, 8)});
  Bytes tall = test::read_bytes(dir.file("tiled.exr"));
  put_le32(tall, attribute_value_at(tall, "tiles", "tiledesc") + 4, 4616);
  test::write_bytes(dir.file("tall_tiles.exr"), tall);
  expect_exr_error(dir.file("tall_tiles.exr"), "corrupt EXR");
}

TEST(Exr, UnsupportedVariantsSaySo) {
  TempDir dir;
  const auto expect_unsupported = [&](const ExrSpec& spec, const std::string& name,
                                      const std::string& what) {
    test::write_bytes(dir.file(name), build_exr(spec, position_sample));
    expect_exr_error(dir.file(name), "unsupported EXR");
    expect_exr_error(dir.file(name), what);
  };
  ExrSpec spec;
  spec.version = 2 | 0x1000;
  expect_unsupported(spec, "multipart.exr", "multi-part");
  spec.version = 2 | 0x800;
  expect_unsupported(spec, "deep.exr", "deep");
  spec.version = 3;
  expect_unsupported(spec, "version3.exr", "format version 3");
  spec = ExrSpec{};
  spec.channels = {{"Z", 2}};
  expect_unsupported(spec, "depth.exr", "no R, G, B channels");
  spec.channels = {{"B", 2}, {"R", 2}}; // G missing
  expect_unsupported(spec, "two.exr", "found: B R");
  spec = ExrSpec{};
  spec.sampling = 2;
  expect_unsupported(spec, "subsampled.exr", "subsampled");
}

/// Every file either reads, giving a framebuffer of finite values, or throws specula::Error
/// naming the file with a one-line message; never a crash, a hang or another exception type.
TEST(Exr, CorruptedCompressedFilesReadOrThrowError) {
  TempDir dir;
  const Framebuffer image = smooth_image(24, 20);
  std::vector<Bytes> valid;
  const auto add = [&](const std::vector<ChannelData>& channels, const OpenExrLayout& layout) {
    write_openexr(dir.file("base.exr"), 24, 20, channels, layout);
    valid.push_back(test::read_bytes(dir.file("base.exr")));
  };
  for (const Imf::Compression compression :
       {Imf::RLE_COMPRESSION, Imf::ZIPS_COMPRESSION, Imf::ZIP_COMPRESSION, Imf::PIZ_COMPRESSION,
        Imf::PXR24_COMPRESSION, Imf::B44_COMPRESSION, Imf::B44A_COMPRESSION, Imf::DWAA_COMPRESSION,
        Imf::DWAB_COMPRESSION}) {
    add(rgb_channels(image, Imf::HALF), {compression, {0, 0}, std::nullopt});
  }
  add(rgb_channels(image, Imf::FLOAT), {Imf::ZIP_COMPRESSION, {0, 0}, Imf::TileDescription(8, 8)});
  add(rgb_channels(image, Imf::FLOAT), {Imf::PIZ_COMPRESSION, {0, 0}, std::nullopt});
  write_exr(image, dir.file("base.exr")); // and what Specula writes itself
  valid.push_back(test::read_bytes(dir.file("base.exr")));

  std::mt19937 rng(2024);
  constexpr int kMutantsPerFile = 200;
  int read_ok = 0;
  int refused = 0;
  for (std::size_t f = 0; f < valid.size(); ++f) {
    const Bytes& original = valid[f];
    for (int m = 0; m < kMutantsPerFile; ++m) {
      Bytes mutant = original;
      // Byte flips (1 to 8 bytes anywhere, or all in the header's first 400 bytes, where
      // sizes live), then a truncation one time in four.
      const auto flips = std::uniform_int_distribution<int>(1, 8)(rng);
      const bool header_only = std::uniform_int_distribution<int>(0, 1)(rng) == 0;
      const std::size_t span =
          header_only ? std::min<std::size_t>(400, mutant.size()) : mutant.size();
      for (int k = 0; k < flips; ++k) {
        const auto at = std::uniform_int_distribution<std::size_t>(0, span - 1)(rng);
        mutant[at] ^= static_cast<std::uint8_t>(std::uniform_int_distribution<int>(1, 255)(rng));
      }
      if (std::uniform_int_distribution<int>(0, 3)(rng) == 0) {
        mutant.resize(std::uniform_int_distribution<std::size_t>(1, mutant.size() - 1)(rng));
      }
      const auto path = dir.file("mutant" + std::to_string(f) + "_" + std::to_string(m) + ".exr");
      test::write_bytes(path, mutant);
      try {
        const Framebuffer back = read_exr(path);
        for (const vec3& p : back.pixels()) {
          ASSERT_TRUE(std::isfinite(p.r) && std::isfinite(p.g) && std::isfinite(p.b)) << path;
        }
        ++read_ok;
      } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(path.filename().string()), std::string::npos) << what;
        EXPECT_EQ(what.find('\n'), std::string::npos) << what;
        ++refused;
      }
      std::filesystem::remove(path);
    }
  }
  // Most mutants must be caught: a reader that accepted everything would not be checking.
  EXPECT_EQ(read_ok + refused, static_cast<int>(valid.size()) * kMutantsPerFile);
  EXPECT_GT(refused, read_ok);
}

TEST(ImageFiles, DispatchByExtensionCaseInsensitive) {
  TempDir dir;
  const Framebuffer image = test::random_image(5, 4, 11);
  write_image(image, dir.file("a.EXR"));
  EXPECT_EQ(read_image(dir.file("a.EXR")), image);
  write_image(image, dir.file("a.Png"));
  EXPECT_EQ(read_image(dir.file("a.Png")).width(), 5u);
  expect_error([](const std::filesystem::path& p) { return read_image(p); }, dir.file("a.bmp"),
               "extension");
  EXPECT_THROW(write_image(image, dir.file("a.jpg")), Error);
}

} // namespace
} // namespace specula
