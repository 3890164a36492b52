// image_header.h: the size read from a header alone is the size read_image decodes, for files
// from Specula and from the OpenEXR library itself (scan lines and tiles, a moved data window);
// malformed headers are left to the reader (empty).

#include "specula/image/image_header.h"
#include "specula/image/image_io.h"
#include "test_support.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfTiledOutputFile.h>

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

namespace specula {
namespace {

/// A file written by the OpenEXR library: R, G, B FLOAT, the data window moved off the origin.
void write_library_exr(const std::filesystem::path& path, int width, int height, bool tiled) {
  Imf::Header header(width, height);
  header.dataWindow() = Imath::Box2i(Imath::V2i(-3, 5), Imath::V2i(-3 + width - 1, 5 + height - 1));
  header.compression() = Imf::PIZ_COMPRESSION;
  std::vector<float> values(static_cast<std::size_t>(width) * height, 0.25f);
  Imf::FrameBuffer slices;
  for (const char* name : {"R", "G", "B"}) {
    header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    slices.insert(name, Imf::Slice::Make(Imf::FLOAT, values.data(), header.dataWindow().min, width,
                                         height, sizeof(float), sizeof(float) * width));
  }
  if (tiled) {
    header.setTileDescription(Imf::TileDescription(16, 8));
    Imf::TiledOutputFile file(path.c_str(), header);
    file.setFrameBuffer(slices);
    file.writeTiles(0, file.numXTiles() - 1, 0, file.numYTiles() - 1);
  } else {
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(slices);
    file.writePixels(height);
  }
}

void expect_header_matches_reader(const std::filesystem::path& path) {
  const std::optional<ImageHeader> header = read_image_header(path);
  ASSERT_TRUE(header) << path;
  const Framebuffer image = read_image(path);
  EXPECT_EQ(header->width, image.width()) << path;
  EXPECT_EQ(header->height, image.height()) << path;
  EXPECT_EQ(header->file_bytes, std::filesystem::file_size(path));
  EXPECT_GE(header->decode_bytes, header->file_bytes) << "the reader holds the whole file";
}

TEST(ImageHeader, SizesAreTheOnesTheReaderDecodes) {
  test::TempDir dir;
  for (const auto& [w, h] :
       std::vector<std::pair<std::uint32_t, std::uint32_t>>{{1, 1}, {37, 5}, {5, 37}, {300, 2}}) {
    const Framebuffer image = test::random_image(w, h, w * 31 + h);
    const std::string stem = std::to_string(w) + "x" + std::to_string(h);
    write_png(image, dir.file(stem + ".png"));
    write_exr(image, dir.file(stem + ".exr"));
    expect_header_matches_reader(dir.file(stem + ".png"));
    expect_header_matches_reader(dir.file(stem + ".exr"));
    write_library_exr(dir.file(stem + "_lines.exr"), int(w), int(h), false);
    write_library_exr(dir.file(stem + "_tiles.exr"), int(w), int(h), true);
    expect_header_matches_reader(dir.file(stem + "_lines.exr"));
    expect_header_matches_reader(dir.file(stem + "_tiles.exr"));
  }
}

TEST(ImageHeader, SixteenBitPngsCostMoreToDecode) {
  // The same size at 16 bits per channel: stb's buffers are twice as large.
  test::TempDir dir;
  write_png(Framebuffer(64, 64), dir.file("8.png"));
  std::string bytes;
  {
    std::ifstream in(dir.file("8.png"), std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes[24] = 16; // bit depth in IHDR: only the header is read
  std::ofstream(dir.file("16.png"), std::ios::binary) << bytes;
  const auto eight = read_image_header(dir.file("8.png"));
  const auto sixteen = read_image_header(dir.file("16.png"));
  ASSERT_TRUE(eight && sixteen);
  EXPECT_GE(sixteen->decode_bytes, eight->decode_bytes + 64 * 64 * 8);
}

TEST(ImageHeader, MalformedHeadersAreLeftToTheReader) {
  test::TempDir dir;
  write_png(Framebuffer(8, 8), dir.file("good.png"));
  write_exr(Framebuffer(8, 8), dir.file("good.exr"));
  std::string png;
  std::string exr;
  {
    std::ifstream a(dir.file("good.png"), std::ios::binary);
    png.assign(std::istreambuf_iterator<char>(a), {});
    std::ifstream b(dir.file("good.exr"), std::ios::binary);
    exr.assign(std::istreambuf_iterator<char>(b), {});
  }
  const auto write = [&](const std::string& name, const std::string& bytes) {
    std::ofstream(dir.file(name), std::ios::binary) << bytes;
    return dir.file(name);
  };
  std::string zero_width = png;
  zero_width.replace(16, 4, std::string(4, '\0'));
  std::string huge = png;
  huge.replace(16, 4, "\x00\x01\x00\x00"); // 65536
  std::string exr_big_attribute = exr;
  // The first attribute's size field follows "channels\0chlist\0": declare 2 GiB.
  exr_big_attribute.replace(8 + 9 + 7, 4, "\x00\x00\x00\x80");
  for (const std::filesystem::path& path :
       {write("short.png", png.substr(0, 20)), write("zero.png", zero_width),
        write("huge.png", huge), write("png_in.exr", png), write("exr_in.png", exr),
        write("short.exr", exr.substr(0, 30)), write("big_attribute.exr", exr_big_attribute),
        dir.file("missing.png"), dir.file("good.jpg")}) {
    EXPECT_FALSE(read_image_header(path)) << path;
  }
  EXPECT_TRUE(read_image_header(dir.file("good.png")));
  EXPECT_TRUE(read_image_header(dir.file("good.exr")));
}

} // namespace
} // namespace specula
