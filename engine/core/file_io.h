#pragma once
/// \file
/// Reading input files whole, within a size bound, from regular files only. Every reader of user
/// input (scenes, meshes, glTF buffers, images) goes through here, so that a device (/dev/zero,
/// /dev/urandom) or a FIFO named like a scene file is an error instead of a read that never ends
/// or blocks, and a file larger than its format's bound is refused before anything is read.
/// The bounds are listed in docs/limits.md.

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace specula {

/// Largest Specula JSON scene file (text that becomes a DOM several times its size).
inline constexpr std::uint64_t kMaxSceneTextBytes = std::uint64_t(256) << 20;
/// Largest binary or bulk input: mesh files, .gltf/.glb, glTF external buffers and images, PNG
/// and EXR files.
inline constexpr std::uint64_t kMaxDataFileBytes = std::uint64_t(2) << 30;

/// The size of `path` in bytes, after checking, with stat() only (opening a FIFO would block),
/// that it names an existing regular file (symbolic links followed) of at most `max_bytes`.
/// Throws specula::Error naming the file: "file not found", "is a directory, not a WHAT",
/// "not a regular file (a character device): a WHAT must be a regular file", "cannot access: ..."
/// or "the file is N bytes, more than the limit of M bytes for a WHAT (docs/limits.md)".
/// `what` names the expected content in messages ("scene file", "mesh file", "PNG image").
[[nodiscard]] std::uint64_t check_regular_file(const std::filesystem::path& path,
                                               std::uint64_t max_bytes, std::string_view what);

/// The whole content of `path`, after check_regular_file(path, max_bytes, what). The file is
/// opened without blocking and checked again on the open descriptor (it may have been replaced
/// since the stat), then read in a loop that stops after `max_bytes` whatever the size claimed,
/// so a file that grows while it is read cannot exceed the bound either. An empty file gives an
/// empty string: whether that is an error is the caller's to say.
[[nodiscard]] std::string read_file_bounded(const std::filesystem::path& path,
                                            std::uint64_t max_bytes, std::string_view what);

/// Bytes of physical memory on this machine (sysconf), or 0 when unknown.
[[nodiscard]] std::uint64_t physical_memory_bytes();

} // namespace specula
