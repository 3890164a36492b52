#pragma once
/// \file
/// What every system is given besides the registry: the tick number and time.

#include <cstdint>

namespace specula {

struct FrameContext {
  std::uint64_t tick = 0; ///< 1 for the first tick of a schedule (0 is "at load")
  double time = 0.0;      ///< seconds since the schedule started, after this tick's dt
  double dt = 0.0;        ///< seconds advanced by this tick
};

} // namespace specula
