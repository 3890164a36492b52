#pragma once
/// \file
/// The games' front ends: headless replay of a recorded input file (tests, CI, measuring) and
/// the window (built only where specula::present exists).

#include "game.h"
#include "input_script.h"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace specula::games {

/// Fixed step of every frame, replayed or played.
inline constexpr double kFrameDt = 1.0 / 60.0;

struct HeadlessOptions {
  std::uint64_t frames = 1;
  std::filesystem::path input;
  std::optional<std::filesystem::path> out;   ///< the final frame, PNG
  std::optional<std::filesystem::path> stats; ///< stats JSON
  std::uint32_t width = 320;
  std::uint32_t height = 180;
  std::string backend = "auto";
  std::optional<TraceMode> mode; ///< none: the game's own (both games: Whitted)
};

struct HeadlessResult {
  std::uint64_t frames = 0;
  double mean_ms = 0.0;               ///< per frame: game step and schedule tick
  std::uint64_t nonfinite_frames = 0; ///< frames with a NaN or infinite pixel or sample
  std::int64_t first_nonfinite_frame = -1;
};

/// Replays `script` for options.frames frames of kFrameDt: step, then one schedule tick that
/// renders; checks every frame's pixels are finite; writes the final frame and the stats.
HeadlessResult run_headless(Game& game, const std::string& game_name, const InputScript& script,
                            const HeadlessOptions& options);

/// Parses the command line and runs a front end. Exit codes: 0, 1 bad input (message names the
/// file and line), 2 unavailable (no window on this build), 3 a non-finite pixel was rendered.
int game_main(int argc, char** argv, const std::string& game_name,
              const std::function<std::unique_ptr<Game>()>& make_game);

struct WindowedOptions {
  std::uint32_t width = 960;
  std::uint32_t height = 540;
  std::string backend = "auto";
  std::optional<TraceMode> mode;
  std::optional<std::filesystem::path> record; ///< write the input played, replayable headless
  /// Play this recording instead of the keyboard (a demo in the window); Esc still quits.
  std::optional<InputScript> input;
  std::optional<std::uint64_t> frames;      ///< close after this many frames (none: on close)
  std::optional<std::filesystem::path> out; ///< the final frame, PNG
  /// Dynamic resolution: the frame rate held by rendering below the window's size
  /// (specula::ResolutionGovernor); 0: always the full size.
  double target_fps = 30.0;
};

/// Plays in a window until it is closed or options.frames have been shown (needs
/// specula::present). With the same input, frames and size the final frame equals
/// run_headless's: both step by kFrameDt and render through the same schedule.
int run_windowed(Game& game, const std::string& game_name, const WindowedOptions& options);

} // namespace specula::games
