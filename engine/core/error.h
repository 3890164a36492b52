#pragma once
/// \file
/// Runtime errors with context (files, fields, lines). Bugs are caught by SPECULA_ASSERT instead;
/// expected absences are std::optional (three error tiers, as in Falcor).

#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>

namespace specula {

/// `text` made safe to print inside a one-line message: control and non-ASCII bytes escaped
/// (\n, \t, \0, \xNN), and anything past `max_bytes` cut with a note of the full length
/// ("...[1048576 bytes]"). Use it for every piece of user input echoed in a message.
[[nodiscard]] std::string printable(std::string_view text, std::size_t max_bytes = 96);

/// A multi-line message (a library's report) folded into one line: line breaks become "; ",
/// other control bytes are escaped and the whole is cut to `max_bytes`.
[[nodiscard]] std::string one_line(std::string_view text, std::size_t max_bytes = 512);

/// A runtime failure with the place it happened: a file, optionally a line or a field path.
/// what() reads "FILE:LINE: MESSAGE" or "FILE: FIELD: MESSAGE", ready to print. Every part is
/// passed through printable()/one_line() on construction, so no message carries raw control
/// bytes, line breaks or megabytes of echoed input, whatever its call site did.
class Error : public std::runtime_error {
public:
  explicit Error(const std::string& message);
  Error(std::string file, const std::string& message);
  Error(std::string file, int line, const std::string& message);
  Error(std::string file, std::string field, const std::string& message);

  [[nodiscard]] const std::string& file() const noexcept { return file_; }
  [[nodiscard]] int line() const noexcept { return line_; }
  [[nodiscard]] const std::string& field() const noexcept { return field_; }
  /// The message without the location prefix.
  [[nodiscard]] const std::string& message() const noexcept { return message_; }

private:
  std::string file_;
  std::string field_;
  std::string message_;
  int line_ = 0;
};

/// Exit code of the `specula` program for bad input (files, values).
inline constexpr int kExitBadInput = 1;
/// Exit code for a feature that is not available (yet) on this build or machine.
inline constexpr int kExitUnavailable = 2;

/// Thrown when a requested feature (backend, mode) does not exist yet or on this machine.
class UnavailableError : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

} // namespace specula
