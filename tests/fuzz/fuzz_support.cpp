#include "fuzz_support.h"

#include "specula/core/log.h"

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <system_error>

#include <unistd.h>

namespace specula::fuzz {
namespace {

namespace fs = std::filesystem;

void write_file(const fs::path& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) finding("cannot write the scratch file " + path.string());
}

// Meshes a fuzzed JSON scene can name as {"file": "cube.obj"} (the dictionary lists the names).
constexpr std::string_view kCubeObj = "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\n"
                                      "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
                                      "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
constexpr std::string_view kTriStl = "solid t\nfacet normal 0 0 1\nouter loop\n"
                                     "vertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                     "endloop\nendfacet\nendsolid t\n";

fs::path make_scratch_dir() {
  // Readers' warnings (skipped glTF channels and the like) on every input would slow fuzzing down
  // and bury its report; SPECULA_FUZZ_LOG=1 keeps them, to look at one input.
  if (std::getenv("SPECULA_FUZZ_LOG") == nullptr) set_log_level(LogLevel::Silent);
  const fs::path dir = fs::temp_directory_path() / ("specula-fuzz-" + std::to_string(::getpid()));
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) finding("cannot create the scratch folder " + dir.string() + ": " + ec.message());
  write_file(dir / "cube.obj", kCubeObj);
  write_file(dir / "tri.stl", kTriStl);
  std::atexit([] {
    std::error_code ignored;
    fs::remove_all(scratch_dir(), ignored);
  });
  return dir;
}

} // namespace

const fs::path& scratch_dir() {
  static const fs::path dir = make_scratch_dir();
  return dir;
}

fs::path write_input(std::span<const std::uint8_t> data, std::string_view name) {
  const fs::path path = scratch_dir() / name;
  write_file(path, std::string_view(reinterpret_cast<const char*>(data.data()), data.size()));
  return path;
}

void finding(std::string_view what) {
  std::fprintf(stderr, "specula fuzz finding: %.*s\n", static_cast<int>(what.size()), what.data());
  std::fflush(stderr);
  std::abort();
}

} // namespace specula::fuzz
