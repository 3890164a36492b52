// Replays a harness without libFuzzer, for ctest in every build (docs/fuzzing.md): runs
// LLVMFuzzerTestOneInput once over every file of the folders (or files) named on the command
// line, in sorted order. A folder that does not exist counts as empty (a reader may have no
// regressions yet), but replaying nothing at all is a failure: a wrong corpus path must not pass.
// Names starting with '.' are skipped. A crash, sanitizer report or fuzz::finding ends the run;
// the file being replayed is printed first, so the failing one is the last name in the log.

#include "fuzz_support.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace fs = std::filesystem;

// Under ASan, an allocation over 1 GB is a finding here too, as with scripts/fuzz.sh's
// -malloc_limit_mb: a small input must not get a huge block, even one never touched (which costs
// nothing without ASan and would pass unseen).
#if defined(__SANITIZE_ADDRESS__)
#define SPECULA_REPLAY_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SPECULA_REPLAY_ASAN 1
#endif
#endif
#ifdef SPECULA_REPLAY_ASAN
extern "C" const char* __asan_default_options() { return "max_allocation_size_mb=1024"; }
#endif

namespace {

std::vector<std::uint8_t> read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "replay: cannot read %s\n", path.c_str());
    std::exit(1);
  }
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

} // namespace

int main(int argc, char** argv) {
  std::vector<fs::path> files;
  for (int i = 1; i < argc; ++i) {
    const fs::path arg = argv[i];
    std::error_code ec;
    if (fs::is_regular_file(arg, ec)) {
      files.push_back(arg);
    } else if (fs::is_directory(arg, ec)) {
      for (const fs::directory_entry& e : fs::directory_iterator(arg))
        if (e.is_regular_file() && !e.path().filename().string().starts_with("."))
          files.push_back(e.path());
    } else {
      std::printf("replay: %s does not exist: nothing from it\n", arg.c_str());
    }
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) {
    std::fprintf(stderr, "replay: no input to replay\n");
    return 1;
  }
  for (const fs::path& file : files) {
    std::printf("replay: %s\n", file.c_str());
    std::fflush(stdout);
    const std::vector<std::uint8_t> bytes = read_bytes(file);
    // A copy of exactly the file's size, so ASan sees a read past the end as libFuzzer would.
    const std::vector<std::uint8_t> copy(bytes);
    LLVMFuzzerTestOneInput(copy.data(), copy.size());
  }
  std::printf("replay: %zu inputs, no finding\n", files.size());
  return 0;
}
