#pragma once
/// \file
/// Minimal leveled logging to stderr. Not for hot paths.

#include <string_view>

namespace specula {

enum class LogLevel { Debug = 0, Info = 1, Warning = 2, Error = 3, Silent = 4 };

/// Messages below this level are dropped (default Info; SPECULA_LOG=debug|info|warning|error|silent).
void set_log_level(LogLevel level);
[[nodiscard]] LogLevel log_level();
void log(LogLevel level, std::string_view message);

inline void log_info(std::string_view m) { log(LogLevel::Info, m); }
inline void log_warning(std::string_view m) { log(LogLevel::Warning, m); }
inline void log_debug(std::string_view m) { log(LogLevel::Debug, m); }

} // namespace specula
