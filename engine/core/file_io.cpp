#include "specula/core/file_io.h"

#include "specula/core/error.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <system_error>

namespace specula {
namespace {

std::string errno_text(int error) {
  return std::error_code(error, std::generic_category()).message();
}

[[nodiscard]] const char* kind_of(mode_t mode) {
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a file";
}

/// The checks both stat() and fstat() results go through.
std::uint64_t check_status(const std::filesystem::path& path, const struct stat& status,
                           std::uint64_t max_bytes, std::string_view what) {
  if (S_ISDIR(status.st_mode))
    throw Error(path.string(), "is a directory, not a " + std::string(what));
  if (!S_ISREG(status.st_mode))
    throw Error(path.string(), std::string("not a regular file (") + kind_of(status.st_mode) +
                                   "): a " + std::string(what) + " must be a regular file");
  const auto size = static_cast<std::uint64_t>(status.st_size);
  if (size > max_bytes)
    throw Error(path.string(), "the file is " + std::to_string(size) +
                                   " bytes, more than the limit of " + std::to_string(max_bytes) +
                                   " bytes for a " + std::string(what) + " (docs/limits.md)");
  return size;
}

/// Closes a descriptor on every path out.
struct Descriptor {
  int fd = -1;
  Descriptor() = default;
  Descriptor(const Descriptor&) = delete;
  Descriptor& operator=(const Descriptor&) = delete;
  ~Descriptor() {
    if (fd >= 0) ::close(fd);
  }
};

} // namespace

std::uint64_t check_regular_file(const std::filesystem::path& path, std::uint64_t max_bytes,
                                 std::string_view what) {
  struct stat status {};
  if (::stat(path.c_str(), &status) != 0) {
    const int error = errno;
    if (error == ENOENT || error == ENOTDIR) throw Error(path.string(), "file not found");
    throw Error(path.string(), "cannot access: " + errno_text(error));
  }
  return check_status(path, status, max_bytes, what);
}

std::string read_file_bounded(const std::filesystem::path& path, std::uint64_t max_bytes,
                              std::string_view what) {
  (void)check_regular_file(path, max_bytes, what);
  // O_NONBLOCK: should a FIFO have taken the file's place since the stat, open() must not wait
  // for a writer; the fstat below then refuses it. Regular files ignore the flag.
  Descriptor file;
  file.fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (file.fd < 0) throw Error(path.string(), "cannot open the file: " + errno_text(errno));
  struct stat status {};
  if (::fstat(file.fd, &status) != 0)
    throw Error(path.string(), "cannot read the file: " + errno_text(errno));
  const std::uint64_t size = check_status(path, status, max_bytes, what);

  // Sized by stat, then read to the end of the file, which may have grown since (or, as in
  // /proc, report size 0): never past one byte beyond the bound.
  std::string bytes(static_cast<std::size_t>(size), '\0');
  std::uint64_t used = 0;
  const auto read_some = [&](char* into, std::uint64_t room) -> std::uint64_t {
    for (;;) {
      const ssize_t n = ::read(file.fd, into, static_cast<std::size_t>(room));
      if (n >= 0) return static_cast<std::uint64_t>(n);
      if (errno != EINTR) throw Error(path.string(), "cannot read the file: " + errno_text(errno));
    }
  };
  while (used < size) {
    const std::uint64_t n = read_some(bytes.data() + used, size - used);
    if (n == 0) break; // shrank since the stat
    used += n;
  }
  bytes.resize(static_cast<std::size_t>(used));
  if (used == size) {
    std::array<char, 64 * 1024> chunk{};
    while (used <= max_bytes) {
      const std::uint64_t n =
          read_some(chunk.data(), std::min<std::uint64_t>(chunk.size(), max_bytes + 1 - used));
      if (n == 0) break;
      bytes.append(chunk.data(), static_cast<std::size_t>(n));
      used += n;
    }
  }
  if (used > max_bytes)
    throw Error(path.string(), "the file grew past the limit of " + std::to_string(max_bytes) +
                                   " bytes for a " + std::string(what) +
                                   " while it was read (docs/limits.md)");
  return bytes;
}

std::uint64_t physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES);
  const long page_size = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page_size <= 0) return 0;
  return static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page_size);
}

} // namespace specula
