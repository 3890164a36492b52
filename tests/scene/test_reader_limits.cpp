// The readers' resource limits and their refusals (docs/limits.md), on inputs built here in
// scratch folders: JSON nesting (tinygltf's recursion overflowed the stack at 20,000 levels),
// PLY headers that made OpenMesh loop for ever, devices and FIFOs named like input files (read
// for ever, or blocking), files over the size bounds, counts over the mesh limits, and what the
// messages echo. Each class is an error naming the file, in bounded time, before allocation.

#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/image/image_io.h"
#include "specula/scene/gltf_loader.h"
#include "specula/scene/mesh_io.h"
#include "specula/scene/scene.h"
#include "specula/scene/strict_json.h"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <string>
#include <vector>

namespace specula {
namespace {

namespace fs = std::filesystem;

/// A fresh scratch folder for one test (ctest runs tests in parallel), removed at the end.
class ScratchDir {
public:
  explicit ScratchDir(const std::string& name)
      : path_(fs::temp_directory_path() / ("specula_test_reader_limits_" + name)) {
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~ScratchDir() { fs::remove_all(path_); }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  [[nodiscard]] fs::path file(const std::string& name) const { return path_ / name; }

private:
  fs::path path_;
};

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

/// The message of the specula::Error `load` throws; fails the test when it throws none.
std::string error_of(const std::function<void()>& load) {
  try {
    load();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no error";
  return {};
}

/// error_of(load), where `load` may open the FIFO `fifo` and block on it waiting for a writer.
/// Should it still be running after a generous while, the test fails and a writer comes and goes
/// so that the blocked open returns, instead of the test hanging until ctest's timeout.
std::string error_without_blocking(const fs::path& fifo, const std::function<void()>& load) {
  auto result = std::async(std::launch::async, [&] { return error_of(load); });
  if (result.wait_for(std::chrono::seconds(30)) == std::future_status::timeout) {
    ADD_FAILURE() << "still reading " << fifo << " after 30 s: blocked on the FIFO";
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) ::close(fd);
  }
  return result.get();
}

/// Whether `text` contains `part`, saying what it is when not (evaluates `text` once).
testing::AssertionResult contains(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return testing::AssertionSuccess();
  return testing::AssertionFailure() << "'" << part << "' not in: " << text;
}
#define EXPECT_CONTAINS(text, part) EXPECT_TRUE(contains(text, part))

/// `depth` nested arrays: "[[[...]]]".
std::string nested_arrays(std::size_t depth) {
  return std::string(depth, '[') + std::string(depth, ']');
}

/// A glTF document of one empty node whose "extras" holds `extras`.
std::string gltf_with_extras(const std::string& extras) {
  return R"({"asset": {"version": "2.0"}, "nodes": [{"name": "n"}], "extras": )" + extras + "}";
}

void put_u32(std::string& out, std::uint32_t v) {
  for (int b = 0; b < 4; ++b) out += static_cast<char>((v >> (8 * b)) & 0xff);
}

/// A GLB holding `json` as its JSON chunk (padded with spaces, as the format asks) and no BIN.
std::string glb_of(std::string json) {
  while (json.size() % 4 != 0) json += ' ';
  std::string out = "glTF";
  put_u32(out, 2);
  put_u32(out, static_cast<std::uint32_t>(12 + 8 + json.size()));
  put_u32(out, static_cast<std::uint32_t>(json.size()));
  put_u32(out, 0x4E4F534A); // "JSON"
  return out + json;
}

// ---------------------------------------------------------------------------------------------
// JSON nesting

std::string nesting_error(std::string_view text, std::size_t limit = strict_json::kMaxJsonNesting) {
  return error_of([&] { strict_json::check_nesting(strict_json::Reader("n.json"), text, limit); });
}

TEST(JsonNesting, TheLimitIsAllowedOneMoreIsNot) {
  const strict_json::Reader r("n.json");
  EXPECT_NO_THROW(strict_json::check_nesting(r, nested_arrays(strict_json::kMaxJsonNesting)));
  const std::string mixed = "{\"a\": [1, {\"b\": []}], \"c\": {}}"; // 4 deep
  EXPECT_NO_THROW(strict_json::check_nesting(r, mixed, 4));
  EXPECT_CONTAINS(nesting_error(mixed, 3), "depth 4 exceeds the limit of 3");
  const std::string message = nesting_error(nested_arrays(strict_json::kMaxJsonNesting + 1));
  EXPECT_CONTAINS(message, "n.json: JSON nesting depth 257 exceeds the limit of 256");
}

TEST(JsonNesting, BracketsInsideStringsDoNotCount) {
  const strict_json::Reader r("n.json");
  // Brackets in strings, escaped quotes and backslashes that must not end or prolong a string.
  const std::string inside =
      "\"" + std::string(10'000, '[') + "\\\"" + std::string(10'000, '{') + "\\\\\"";
  EXPECT_NO_THROW(strict_json::check_nesting(r, "[" + inside + ", \"\\\\\", \"]]]\"]", 1));
  // After an escaped backslash the quote does end the string: the brackets after it count.
  EXPECT_CONTAINS(nesting_error("[\"\\\\\", [[]]]", 2), "depth 3");
}

TEST(JsonNesting, ErrorNamesTheLineWhereTheLimitWasFirstExceeded) {
  const std::string text = "{\n\"a\":\n" + nested_arrays(300) + "\n}";
  EXPECT_CONTAINS(nesting_error(text),
                  "depth 301 exceeds the limit of 256 (first exceeded at line 3");
}

TEST(JsonNesting, DeepGltfAndGlbAreErrorsBeforeTinygltfParsesThem) {
  // 20,000 levels overflowed tinygltf's stack; a million are as quick to refuse.
  const ScratchDir dir("deep_gltf");
  for (const std::size_t depth : {std::size_t(20'000), std::size_t(1'000'000)}) {
    const std::string json = gltf_with_extras(nested_arrays(depth));
    const std::string expected =
        "JSON nesting depth " + std::to_string(depth + 1) + " exceeds the limit of 256";
    write_bytes(dir.file("deep.gltf"), json);
    write_bytes(dir.file("deep.glb"), glb_of(json));
    for (const char* name : {"deep.gltf", "deep.glb"}) {
      SCOPED_TRACE(name);
      const fs::path path = dir.file(name);
      const std::string message = error_of([&] { (void)load_gltf_scene(path); });
      EXPECT_CONTAINS(message, path.string() + ": " + expected);
      EXPECT_CONTAINS(error_of([&] { (void)load_gltf_mesh(path, 0); }), expected);
    }
  }
}

TEST(JsonNesting, GltfAndGlbAtTheLimitLoad) {
  const ScratchDir dir("limit_gltf");
  // The root object is one level; "extras" takes the rest. Its strings hold brackets that a
  // scan confused by strings would count far past the limit.
  const std::string noise = R"("\"[[[[[[[[[[{{{{{{{{\\")";
  const std::string extras = std::string(strict_json::kMaxJsonNesting - 2, '[') + "[" + noise +
                             "]" + std::string(strict_json::kMaxJsonNesting - 2, ']');
  const std::string json = gltf_with_extras(extras);
  write_bytes(dir.file("limit.gltf"), json);
  write_bytes(dir.file("limit.glb"), glb_of(json));
  EXPECT_NO_THROW((void)load_gltf_scene(dir.file("limit.gltf")));
  EXPECT_NO_THROW((void)load_gltf_scene(dir.file("limit.glb")));
  write_bytes(dir.file("over.gltf"), gltf_with_extras("[" + extras + "]"));
  EXPECT_CONTAINS(error_of([&] { (void)load_gltf_scene(dir.file("over.gltf")); }),
                  "depth 257 exceeds the limit of 256");
}

TEST(JsonNesting, DeepSpeculaSceneIsAnErrorNamingDepthAndLimit) {
  const ScratchDir dir("deep_json");
  const fs::path path = dir.file("deep.json");
  write_bytes(path,
              R"({"format": "specula-scene", "version": 1, "x": )" + nested_arrays(20'000) + "}");
  EXPECT_CONTAINS(error_of([&] { (void)load_scene(path); }),
                  path.string() + ": JSON nesting depth 20001 exceeds the limit of 256");
}

// ---------------------------------------------------------------------------------------------
// PLY headers. OpenMesh read each of these for ever (a version or count its stream cannot
// convert) or as something else (a version other than 1, a keyword inside a stray line): a hang
// here would show as ctest's timeout.

const std::string kPlyBody = "element vertex 3\n"
                             "property float x\n"
                             "property float y\n"
                             "property float z\n"
                             "element face 1\n"
                             "property list uchar int vertex_indices\n"
                             "end_header\n"
                             "0 0 0\n"
                             "1 0 0\n"
                             "0 1 0\n"
                             "3 0 1 2\n";

std::string ply_error(const ScratchDir& dir, const std::string& text) {
  const fs::path path = dir.file("header.ply");
  write_bytes(path, text);
  std::string message = error_of([&] { (void)load_mesh_file(path); });
  EXPECT_CONTAINS(message, path.string());
  return message;
}

TEST(PlyHeader, VersionMustBeOne) {
  const ScratchDir dir("ply_version");
  for (const char* version :
       {"nan", "NaN", "-nan", "inf", "-inf", "+inf", "infinity", "1e999", "-1e999", "2.0", "-1",
        "0", "1e0", "0.1", "1.5", "11", "x.0", "1.0x"}) {
    SCOPED_TRACE(version);
    for (const char* format : {"ascii", "binary_little_endian"}) {
      const std::string text =
          "ply\nformat " + std::string(format) + " " + version + "\n" + kPlyBody;
      EXPECT_CONTAINS(ply_error(dir, text), "1.0' after 'ply'");
    }
  }
  for (const char* version : {"1.0", "1", "1.00", "01.0"}) {
    SCOPED_TRACE(version);
    write_bytes(dir.file("good.ply"),
                "ply\nformat ascii " + std::string(version) + "\n" + kPlyBody);
    EXPECT_EQ(load_mesh_file(dir.file("good.ply")).triangle_count(), 1U);
  }
}

TEST(PlyHeader, LinesOpenMeshWouldMisreadAreErrors) {
  const ScratchDir dir("ply_lines");
  struct Case {
    const char* line; ///< inserted after the format line
    const char* problem;
  };
  for (const Case& c : {
           Case{"obj_info element vertex 99999999999", "'element' as a keyword"},
           Case{"stray words element face 1e999", "'element' as a keyword"},
           Case{"made by property float w", "'property' as a keyword"},
           Case{"early end_header here", "'end_header' as a keyword"},
           Case{"format ascii nan", "second 'format' line"},
           Case{"element vertex 3 extra", "'element <name> <count>'"},
           Case{"element edge 1e999", "not an integer"},
           Case{"element edge 4294967296", "not an integer from 0 to 2^32 - 1"},
           Case{"element edge -1", "not an integer from 0"},
       }) {
    SCOPED_TRACE(c.line);
    EXPECT_CONTAINS(
        ply_error(dir, "ply\nformat ascii 1.0\n" + std::string(c.line) + "\n" + kPlyBody),
        c.problem);
  }
  EXPECT_CONTAINS(ply_error(dir, "ply\nformat ascii 1.0\n" + kPlyBody + "x\n"), "more values");
  EXPECT_CONTAINS(ply_error(dir, "ply junk\nformat ascii 1.0\n" + kPlyBody), "'ply' alone");
  // A property line of another shape, a duplicate element.
  std::string body = kPlyBody;
  body.replace(body.find("property float z"), 16, "property float z w");
  EXPECT_CONTAINS(ply_error(dir, "ply\nformat ascii 1.0\n" + body), "'property <type> <name>'");
  EXPECT_CONTAINS(ply_error(dir, "ply\nformat ascii 1.0\nelement face 0\n" + kPlyBody),
                  "declared twice");

  // Comments, and stray text without keywords (as in assimp's Wuson.ply), are fine.
  write_bytes(dir.file("stray.ply"), "ply\nformat ascii 1.0\ncomment element vertex 99 format nan\n"
                                     "Created by Blender3D 247 - www.blender.org, source file: \n" +
                                         kPlyBody);
  EXPECT_EQ(load_mesh_file(dir.file("stray.ply")).triangle_count(), 1U);
}

// ---------------------------------------------------------------------------------------------
// Counts beyond the mesh limits, told from the header of a small file.

TEST(MeshCounts, HeadersDeclaringMoreThanTheLimitsAreErrors) {
  const ScratchDir dir("counts");
  const std::string faces = std::to_string(kMaxTriangles + 1);
  const std::string vertices = std::to_string(kMaxVertices + 1);
  std::string ply = "ply\nformat ascii 1.0\n" + kPlyBody;
  ply.replace(ply.find("element face 1"), 14, "element face " + faces);
  EXPECT_CONTAINS(ply_error(dir, ply), faces + " faces, more than the limit of " +
                                           std::to_string(kMaxTriangles) + " triangles");
  ply = "ply\nformat binary_little_endian 1.0\n" + kPlyBody;
  ply.replace(ply.find("element vertex 3"), 16, "element vertex " + vertices);
  EXPECT_CONTAINS(ply_error(dir, ply),
                  vertices + " vertices, more than the limit of " + std::to_string(kMaxVertices));

  write_bytes(dir.file("a.off"), "OFF\n3 " + faces + " 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_CONTAINS(error_of([&] { (void)load_mesh_file(dir.file("a.off")); }),
                  "a.off:2: the mesh has " + faces + " faces, more than the limit");
  std::string binary_off = "OFF BINARY\n";
  put_u32(binary_off, static_cast<std::uint32_t>(kMaxVertices + 1));
  put_u32(binary_off, 1);
  put_u32(binary_off, 0);
  write_bytes(dir.file("b.off"), binary_off);
  EXPECT_CONTAINS(error_of([&] { (void)load_mesh_file(dir.file("b.off")); }),
                  vertices + " vertices, more than the limit");
}

// ---------------------------------------------------------------------------------------------
// Devices and FIFOs named like input files; files over the size bounds.

/// Reads `path` with the reader its extension selects, as the CLI would.
void read_any(const fs::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".png" || ext == ".exr")
    (void)read_image(path);
  else
    (void)load_scene(path);
}

const char* const kInputNames[] = {"x.json", "x.gltf", "x.glb", "x.obj", "x.ply",
                                   "x.off",  "x.stl",  "x.png", "x.exr"};

TEST(NotARegularFile, DevicesAndFifosNamedLikeInputFilesAreRefused) {
  const ScratchDir dir("devices");
  for (const char* name : kInputNames) {
    SCOPED_TRACE(name);
    const fs::path fifo = dir.file(std::string("fifo_") + name);
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    const std::string message = error_without_blocking(fifo, [&] { read_any(fifo); });
    EXPECT_CONTAINS(message, fifo.string() + ": not a regular file (a FIFO)");
    for (const char* device : {"/dev/zero", "/dev/urandom"}) {
      const fs::path link = dir.file(std::string(device + 5) + "_" + name);
      fs::create_symlink(device, link);
      EXPECT_CONTAINS(error_of([&] { read_any(link); }),
                      link.string() + ": not a regular file (a character device)");
    }
  }
}

TEST(NotARegularFile, MeshFileOfAJsonSceneThatIsADeviceSaysSo) {
  const ScratchDir dir("scene_mesh_device");
  fs::create_symlink("/dev/zero", dir.file("zero.obj"));
  const fs::path scene = dir.file("scene.json");
  write_bytes(scene, R"({"format": "specula-scene", "version": 1, "entities": [
                          {"name": "m", "mesh": {"file": "zero.obj"}}]})");
  const std::string message = error_of([&] { (void)load_scene(scene); });
  EXPECT_CONTAINS(message, "mesh file \"zero.obj\" is not a regular file");
  EXPECT_EQ(message.find("not found"), std::string::npos) << message;
}

/// One triangle whose 42 bytes (3 float positions, 3 uint16 indices) are in buffer `uri`.
std::string gltf_with_buffer(const std::string& uri) {
  return R"({"asset": {"version": "2.0"},
    "buffers": [{"uri": ")" +
         uri + R"(", "byteLength": 42}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                    {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]},
                  {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0})";
}

TEST(NotARegularFile, GltfBuffersThatAreDevicesOrFifosAreRefused) {
  const ScratchDir dir("gltf_buffers");
  // The control: the same file with a regular buffer loads.
  std::string buffer;
  for (const float v : {0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f}) {
    std::uint32_t bits = 0;
    std::memcpy(&bits, &v, 4);
    put_u32(buffer, bits);
  }
  buffer += std::string("\0\0\1\0\2\0", 6);
  write_bytes(dir.file("good.bin"), buffer);
  write_bytes(dir.file("good.gltf"), gltf_with_buffer("good.bin"));
  EXPECT_EQ(load_gltf_mesh(dir.file("good.gltf"), 0).triangle_count(), 1U);

  ASSERT_EQ(::mkfifo(dir.file("fifo.bin").c_str(), 0600), 0);
  fs::create_symlink("/dev/zero", dir.file("zero.bin"));
  for (const char* name : {"fifo.bin", "zero.bin"}) {
    SCOPED_TRACE(name);
    const fs::path gltf = dir.file(std::string(name) + ".gltf");
    write_bytes(gltf, gltf_with_buffer(name));
    const std::string message =
        error_without_blocking(dir.file("fifo.bin"), [&] { (void)load_gltf_scene(gltf); });
    EXPECT_CONTAINS(message, gltf.string() + ": glTF: ");
    EXPECT_CONTAINS(message, "not a regular file");
  }
}

TEST(SizeBound, FilesOverTheBoundAreRefusedBeforeReading) {
  // Sparse files: the size is what stat reports, no byte of it is ever written or read.
  const ScratchDir dir("size");
  for (const char* name : kInputNames) {
    SCOPED_TRACE(name);
    const fs::path path = dir.file(name);
    const bool json = path.extension() == ".json";
    const std::uint64_t limit = json ? kMaxSceneTextBytes : kMaxDataFileBytes;
    write_bytes(path, "");
    fs::resize_file(path, limit + 1);
    EXPECT_CONTAINS(error_of([&] { read_any(path); }),
                    path.string() + ": the file is " + std::to_string(limit + 1) +
                        " bytes, more than the limit of " + std::to_string(limit) + " bytes");
  }
}

// ---------------------------------------------------------------------------------------------
// Images whose header asks for more memory than the file can justify.

TEST(ImageSize, PngWhoseHeaderAsksForMoreThanItsDataCanHoldIsRefusedBeforeDecoding) {
  const ScratchDir dir("png");
  // A 16384 x 16384 RGB IHDR (within the side limit) in a 45-byte file: 805 MB of scan lines
  // cannot come out of 45 bytes of deflate. No IDAT is needed to tell.
  std::string png("\x89PNG\r\n\x1a\n", 8);
  const auto be32 = [&](std::uint32_t v) {
    for (int b = 3; b >= 0; --b) png += static_cast<char>((v >> (8 * b)) & 0xff);
  };
  be32(13);
  png += "IHDR";
  be32(16384);
  be32(16384);
  png += std::string("\x08\x02\x00\x00\x00", 5);
  be32(0); // CRC, never reached
  png += std::string("\0\0\0\0IEND\xae\x42\x60\x82", 12);
  write_bytes(dir.file("huge.png"), png);
  EXPECT_CONTAINS(error_of([&] { (void)read_png(dir.file("huge.png")); }),
                  "corrupt or truncated PNG: a 16384x16384 image needs 805322752 bytes of scan "
                  "lines, more than the 45-byte file can hold compressed");
}

// ---------------------------------------------------------------------------------------------
// Messages: one line, input echoed cut and escaped.

bool has_raw_control_byte(const std::string& s) {
  for (const char c : s)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) == 0x7f) return true;
  return false;
}

TEST(ReaderMessages, TinygltfReportsBecomeOneLine) {
  const ScratchDir dir("gltf_lines");
  // tinygltf reports the channel without a sampler on two lines, and the missing image (a
  // warning, read before the animations) on two more.
  write_bytes(dir.file("lines.gltf"),
              R"({"asset": {"version": "2.0"}, "nodes": [{}], "images": [{"uri": "img.png"}],
                  "animations": [{"channels": [{"target": {"path": "translation"}}],
                                  "samplers": []}]})");
  const std::string message = error_of([&] { (void)load_gltf_scene(dir.file("lines.gltf")); });
  EXPECT_CONTAINS(message, "missing in AnimationChannel.; `sampler` field is missing");
  EXPECT_CONTAINS(message, "(File not found : img.png; Failed to load external 'uri' for image[0]");
  EXPECT_FALSE(has_raw_control_byte(message)) << message;
}

TEST(ReaderMessages, LongAndControlCharacterInputIsCutAndEscaped) {
  const ScratchDir dir("echo");
  // Control bytes reach the strings through JSON escapes; raw ones are a syntax error (whose
  // message must be as bounded: the last test below).
  const std::string huge = std::string(1 << 20, 'v') + "\\u0001\\u001b[31m";
  write_bytes(dir.file("version.gltf"), R"({"asset": {"version": "3)" + huge + R"("}})");
  const std::string version_message =
      error_of([&] { (void)load_gltf_scene(dir.file("version.gltf")); });
  EXPECT_CONTAINS(version_message, "is not supported");
  EXPECT_LT(version_message.size(), 2048U);
  EXPECT_FALSE(has_raw_control_byte(version_message));

  write_bytes(dir.file("key.json"),
              R"({"format": "specula-scene", "version": 1, "k\u0000)" + huge + R"(": 1})");
  const std::string key_message = error_of([&] { (void)load_scene(dir.file("key.json")); });
  EXPECT_CONTAINS(key_message, "unknown key \"k\\0vvvv");
  EXPECT_LT(key_message.size(), 2048U);
  EXPECT_FALSE(has_raw_control_byte(key_message));

  write_bytes(dir.file("string.json"), R"({"format": ")" + huge + R"(", "version": 1})");
  const std::string value_message = error_of([&] { (void)load_scene(dir.file("string.json")); });
  EXPECT_CONTAINS(value_message, "got the string \"vvvv");
  EXPECT_LT(value_message.size(), 2048U);
  EXPECT_FALSE(has_raw_control_byte(value_message));

  // Raw control bytes and a megabyte in the token a syntax error quotes.
  write_bytes(dir.file("raw.json"),
              "{\"format\": \"" + std::string(1 << 20, 'v') + std::string("\0\x01\x1b[31m\"}", 7));
  const std::string raw_message = error_of([&] { (void)load_scene(dir.file("raw.json")); });
  EXPECT_CONTAINS(raw_message, "malformed JSON");
  EXPECT_LT(raw_message.size(), 2048U);
  EXPECT_FALSE(has_raw_control_byte(raw_message));
}

} // namespace
} // namespace specula
