#pragma once
/// \file
/// The integrators' names (render_frame.h runs them; the radiance hook is told which one a frame
/// uses).

#include <optional>
#include <string_view>

namespace specula {

enum class TraceMode { Cast, Whitted, Path, Shadow };
[[nodiscard]] std::optional<TraceMode> parse_trace_mode(std::string_view name);
[[nodiscard]] const char* trace_mode_name(TraceMode mode);

} // namespace specula
