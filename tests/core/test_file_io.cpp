// read_file_bounded and check_regular_file: what every input reader goes through. A device, a
// FIFO or a file over the bound is an error from stat alone, before anything is read.

#include "specula/core/file_io.h"

#include "specula/core/error.h"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace specula {
namespace {

namespace fs = std::filesystem;

class ScratchDir {
public:
  explicit ScratchDir(const std::string& name)
      : path_(fs::temp_directory_path() / ("specula_test_file_io_" + name)) {
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

std::string read_error(const fs::path& path, std::uint64_t max_bytes) {
  try {
    (void)read_file_bounded(path, max_bytes, "test file");
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), path.string());
    return e.what();
  }
  ADD_FAILURE() << path << " was read without an error";
  return {};
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

TEST(FileIo, ReadsTheWholeFileByteForByte) {
  const ScratchDir dir("whole");
  std::string bytes;
  for (int i = 0; i < 200'000; ++i) bytes += static_cast<char>(i * 7 + (i >> 8));
  write_text(dir.file("a.bin"), bytes);
  EXPECT_EQ(read_file_bounded(dir.file("a.bin"), bytes.size(), "test file"), bytes);
  write_text(dir.file("empty.bin"), "");
  EXPECT_EQ(read_file_bounded(dir.file("empty.bin"), 10, "test file"), "");
}

TEST(FileIo, FileOverTheBoundIsRefusedNamingSizeAndLimit) {
  const ScratchDir dir("bound");
  write_text(dir.file("eleven.txt"), "12345678901");
  EXPECT_EQ(read_file_bounded(dir.file("eleven.txt"), 11, "test file").size(), 11U);
  const std::string message = read_error(dir.file("eleven.txt"), 10);
  EXPECT_NE(message.find("11 bytes, more than the limit of 10 bytes"), std::string::npos)
      << message;
}

TEST(FileIo, SparseFileOverTheBoundIsRefusedWithoutReadingIt) {
  // 2^40 bytes that the file system never allocates: reading them would take hours.
  const ScratchDir dir("sparse");
  const fs::path path = dir.file("huge.bin");
  write_text(path, "");
  fs::resize_file(path, std::uint64_t(1) << 40);
  const std::string message = read_error(path, kMaxDataFileBytes);
  EXPECT_NE(message.find("more than the limit"), std::string::npos) << message;
}

TEST(FileIo, DevicesFifosAndDirectoriesAreNotRegularFiles) {
  const ScratchDir dir("kinds");
  const fs::path fifo = dir.file("pipe.json");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // Nobody writes to the FIFO: opening it would block, so only stat may look at it.
  EXPECT_NE(read_error(fifo, 1 << 20).find("not a regular file (a FIFO)"), std::string::npos);
  EXPECT_NE(read_error("/dev/zero", 1 << 20).find("not a regular file (a character device)"),
            std::string::npos);
  fs::create_symlink("/dev/urandom", dir.file("random.json"));
  EXPECT_NE(read_error(dir.file("random.json"), 1 << 20).find("not a regular file"),
            std::string::npos);
  EXPECT_NE(read_error(dir.file(""), 1 << 20).find("is a directory"), std::string::npos);
  EXPECT_NE(read_error(dir.file("missing.json"), 1 << 20).find("file not found"),
            std::string::npos);
}

TEST(FileIo, PhysicalMemoryIsKnownHere) { EXPECT_GT(physical_memory_bytes(), std::uint64_t(1) << 20); }

} // namespace
} // namespace specula
