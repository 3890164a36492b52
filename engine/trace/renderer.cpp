#include "specula/trace/renderer.h"

namespace specula {

std::optional<TraceMode> parse_trace_mode(std::string_view name) {
  if (name == "cast") return TraceMode::Cast;
  if (name == "whitted") return TraceMode::Whitted;
  if (name == "path") return TraceMode::Path;
  if (name == "shadow") return TraceMode::Shadow;
  return std::nullopt;
}

const char* trace_mode_name(TraceMode mode) {
  switch (mode) {
  case TraceMode::Cast: return "cast";
  case TraceMode::Whitted: return "whitted";
  case TraceMode::Path: return "path";
  case TraceMode::Shadow: return "shadow";
  }
  return "unknown";
}

} // namespace specula
