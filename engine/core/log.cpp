#include "specula/core/log.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>

namespace specula {
namespace {

LogLevel level_from_environment() {
  const char* env = std::getenv("SPECULA_LOG");
  if (env == nullptr) return LogLevel::Info;
  const std::string v(env);
  if (v == "debug") return LogLevel::Debug;
  if (v == "warning") return LogLevel::Warning;
  if (v == "error") return LogLevel::Error;
  if (v == "silent") return LogLevel::Silent;
  return LogLevel::Info;
}

std::atomic<LogLevel>& current_level() {
  static std::atomic<LogLevel> level{level_from_environment()};
  return level;
}

std::mutex& log_mutex() {
  static std::mutex m;
  return m;
}

} // namespace

void set_log_level(LogLevel level) { current_level().store(level); }
LogLevel log_level() { return current_level().load(); }

void log(LogLevel level, std::string_view message) {
  if (level < current_level().load()) return;
  static constexpr const char* kNames[] = {"debug", "info", "warning", "error", ""};
  const std::lock_guard lock(log_mutex());
  std::fprintf(stderr, "specula [%s] %.*s\n", kNames[static_cast<int>(level)],
               static_cast<int>(message.size()), message.data());
}

} // namespace specula
