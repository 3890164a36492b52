#pragma once
/// \file
/// Runtime errors with context (files, fields, lines). Bugs are caught by SPECULA_ASSERT instead;
/// expected absences are std::optional (three error tiers, as in Falcor).

#include <stdexcept>
#include <string>

namespace specula {

/// A runtime failure with the place it happened: a file, optionally a line or a field path.
/// what() reads "FILE:LINE: MESSAGE" or "FILE: FIELD: MESSAGE", ready to print.
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
