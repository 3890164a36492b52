#pragma once
/// \file
/// What the libFuzzer harnesses of tests/fuzz/ share (docs/fuzzing.md). Specula's readers take
/// paths, and opening and reading the file is part of what is tested, so each input is written to
/// a scratch file first. The one rule every harness checks: an input may be rejected only with
/// specula::Error; any other exception, a crash, a sanitizer report, a hang or a broken promise
/// of the reader (fuzz::finding) is a finding.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>

/// The libFuzzer entry point each harness defines (one per program).
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace specula::fuzz {

/// This process's scratch folder (one per process, so parallel fuzzing jobs never share a file;
/// removed at normal exit). It also holds small valid meshes, cube.obj and tri.stl, that JSON
/// scenes may name as mesh files. The first call also silences the engine's log unless
/// SPECULA_FUZZ_LOG is set.
[[nodiscard]] const std::filesystem::path& scratch_dir();

/// Writes `data` to the file `name` in scratch_dir() (replacing it) and returns its path.
[[nodiscard]] std::filesystem::path write_input(std::span<const std::uint8_t> data,
                                                std::string_view name);

/// Reports a finding that is not a crash (a reader broke its documented promise, or threw
/// something other than specula::Error) and aborts, so libFuzzer keeps the input.
[[noreturn]] void finding(std::string_view what);

/// Runs fn(); a specula::Error is an expected rejection, anything else thrown is a finding.
template <class Fn> void expect_only_errors(Fn&& fn);

} // namespace specula::fuzz

#include "specula/core/error.h"

#include <exception>
#include <string>

template <class Fn> void specula::fuzz::expect_only_errors(Fn&& fn) {
  try {
    fn();
  } catch (const specula::Error&) {
    // The input was rejected with a message naming the file: what bad input must get.
  } catch (const std::exception& e) {
    finding(std::string("exception other than specula::Error: ") + e.what());
  } catch (...) {
    finding("exception of unknown type");
  }
}
