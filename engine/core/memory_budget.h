#pragma once
/// \file
/// How much memory one command may plan to use, and sizes written for people ("512M", "4 GiB").
/// Commands estimate what a request needs from its sizes (image headers, width × height) and
/// refuse it with a clear message before allocating, rather than dying in the middle of it.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace specula {

/// The budget a command gets when the user names none: 3/4 of physical memory
/// (physical_memory_bytes(), core/file_io.h; the rest is left to the system and other programs),
/// and no more than the process's soft address-space or data limit (`ulimit -v`, `ulimit -d`)
/// where one is set. At least 256 MiB, so a machine that reports nothing still renders small
/// images.
[[nodiscard]] std::uint64_t default_memory_budget();

/// A size: a whole or decimal number of bytes with an optional unit K, M, G or T (powers of 1024;
/// "KiB", "MB", "GiB" and lower case are the same), e.g. "512M", "1.5G", "4096". Empty for
/// anything else, for 0, and for sizes beyond 2^63 bytes.
[[nodiscard]] std::optional<std::uint64_t> parse_byte_size(std::string_view text);

/// "12.3 GiB", "512 MiB", "900 bytes": three significant digits, binary units.
[[nodiscard]] std::string byte_size_text(std::uint64_t bytes);

/// The budget of one command and where it came from, for messages.
struct MemoryBudget {
  std::uint64_t bytes = 0;
  std::string origin; ///< e.g. "--memory-limit 4G", or the default and how to change it
};

/// The budget `option` names (parse_byte_size), or default_memory_budget() when it is empty.
/// Throws specula::Error naming `option_name` for a value that is not a size.
[[nodiscard]] MemoryBudget memory_budget(std::string_view option, std::string_view option_name);

/// Throws specula::Error naming `file` when `needed` bytes exceed the budget: "<what> needs about
/// N, more than the memory budget of M (origin)". `what` says what was asked, with its sizes.
void check_memory(std::uint64_t needed, const MemoryBudget& budget, const std::string& file,
                  const std::string& what);

} // namespace specula
