// PNG and OpenEXR files: round trips, every PNG colour type, EXR variants the reader accepts
// (HALF, extra channels, decreasing line order, offset data window), and bad files of every
// kind, each of which must throw specula::Error naming the file.

#include "specula/core/error.h"
#include "specula/image/image_io.h"
#include "specula/image/srgb.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>

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

TEST(Exr, RoundTripIsBitExact) {
  TempDir dir;
  Framebuffer original = test::random_image(19, 11, 99, -100.0f, 100.0f);
  // Values that a careless encoder loses: signed zero, subnormals, extremes.
  original.at(0, 0) = vec3(-0.0f, std::numeric_limits<float>::denorm_min(), 1e-40f);
  original.at(1, 0) = vec3(std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(),
                           std::numeric_limits<float>::min());
  write_exr(original, dir.file("round.exr"));
  const Framebuffer back = read_exr(dir.file("round.exr"));
  ASSERT_EQ(back.width(), original.width());
  ASSERT_EQ(back.height(), original.height());
  EXPECT_EQ(std::memcmp(back.pixels().data(), original.pixels().data(),
                        original.pixel_count() * sizeof(vec3)),
            0);
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

/// A hand-made scan-line EXR, built here independently of the writer under test.
struct ExrSpec {
  std::uint32_t version = 2;
  std::vector<std::pair<std::string, std::int32_t>> channels = {{"B", 2}, {"G", 2}, {"R", 2}};
  std::int32_t sampling = 1;
  std::uint8_t compression = 0;
  std::array<std::int32_t, 4> data_window = {0, 0, 1, 1};
  std::uint8_t line_order = 0; ///< 1: blocks stored bottom line first
  bool with_pixels = true;
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
  LeBytes channels;
  for (const auto& [name, type] : spec.channels) {
    channels.str(name);
    channels.u32(static_cast<std::uint32_t>(type));
    channels.u32(0); // pLinear + reserved
    channels.u32(static_cast<std::uint32_t>(spec.sampling));
    channels.u32(static_cast<std::uint32_t>(spec.sampling));
  }
  channels.u8(0);
  out.attribute("channels", "chlist", channels.bytes);
  out.attribute("compression", "compression", {spec.compression});
  LeBytes window;
  for (std::int32_t v : spec.data_window) window.u32(static_cast<std::uint32_t>(v));
  out.attribute("dataWindow", "box2i", window.bytes);
  out.attribute("displayWindow", "box2i", window.bytes);
  out.attribute("lineOrder", "lineOrder", {spec.line_order});
  LeBytes one;
  one.u32(std::bit_cast<std::uint32_t>(1.0f));
  out.attribute("pixelAspectRatio", "float", one.bytes);
  out.attribute("owner", "string", {'t', 'e', 's', 't'}); // unknown attributes are skipped
  out.attribute("screenWindowCenter", "v2f", Bytes(8, 0));
  out.attribute("screenWindowWidth", "float", one.bytes);
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
  write_png(Framebuffer(2, 2), dir.file("png_inside.exr"));
  expect_exr_error(dir.file("png_inside.exr"), "magic");
  test::write_bytes(dir.file("three.exr"), Bytes{0x76, 0x2F, 0x31});
  expect_exr_error(dir.file("three.exr"), "magic");

  // Truncations of a valid file at every region: version, header, offset table, pixel data.
  write_exr(test::random_image(8, 8, 3), dir.file("valid.exr"));
  const Bytes valid = test::read_bytes(dir.file("valid.exr"));
  for (std::size_t size : {std::size_t{6}, std::size_t{40}, std::size_t{300}, std::size_t{340},
                           valid.size() / 2, valid.size() - 1}) {
    const auto name = "cut" + std::to_string(size) + ".exr";
    test::write_bytes(dir.file(name),
                      Bytes(valid.begin(), valid.begin() + static_cast<long>(size)));
    expect_exr_error(dir.file(name));
  }

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

  // NaN and infinity in pixel data (FLOAT and HALF).
  ExrSpec small;
  test::write_bytes(dir.file("nan.exr"), build_exr(small, [](int x, int y, const std::string& c) {
                      return x == 1 && y == 1 && c == "G"
                                 ? std::bit_cast<std::uint32_t>(
                                       std::numeric_limits<float>::quiet_NaN())
                                 : std::bit_cast<std::uint32_t>(0.25f);
                    }));
  expect_exr_error(dir.file("nan.exr"), "NaN");
  ExrSpec half = small;
  half.channels = {{"B", 1}, {"G", 1}, {"R", 1}};
  test::write_bytes(dir.file("inf.exr"), build_exr(half, [](int x, int, const std::string&) {
                      return x == 0 ? 0x7C00u : 0x3C00u; // +Inf
                    }));
  expect_exr_error(dir.file("inf.exr"), "infinite");
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
  spec.compression = 3;
  expect_unsupported(spec, "zip.exr", "ZIP");
  spec = ExrSpec{};
  spec.version = 2 | 0x200;
  expect_unsupported(spec, "tiled.exr", "tiled");
  spec.version = 2 | 0x1000;
  expect_unsupported(spec, "multipart.exr", "multi-part");
  spec = ExrSpec{};
  spec.channels = {{"B", 2}, {"G", 2}, {"R", 0}};
  expect_unsupported(spec, "uint.exr", "UINT");
  spec.channels = {{"Y", 2}};
  expect_unsupported(spec, "luminance.exr", "no R, G and B");
  spec = ExrSpec{};
  spec.sampling = 2;
  expect_unsupported(spec, "subsampled.exr", "subsampled");
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
