#pragma once
/// \file
/// Recorded input: a text file, one line per frame range, that the headless mode replays and
/// the windowed mode's --record writes.
///
///   # comment
///   FRAME[-LAST] [down=KEY,KEY...] [press=KEY,...] [mouse=DX,DY]
///
/// Frames count from 0; ranges ascend without overlapping; frames not named have no input.
/// Keys: left right up down space. Example: `0-59 down=up` holds up for a second at 60 Hz.

#include "game.h"

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace specula::games {

/// Frames above this are refused (a typo, not a game).
inline constexpr std::uint64_t kMaxScriptFrames = 10'000'000;

struct InputScript {
  std::vector<GameInput> frames; ///< up to the last frame named
  [[nodiscard]] GameInput at(std::uint64_t frame) const {
    return frame < frames.size() ? frames[frame] : GameInput{};
  }
};

/// Parses `text`; throws specula::Error "NAME:LINE: problem" for anything malformed.
[[nodiscard]] InputScript parse_input_script(std::string_view text, const std::string& name);
/// Reads and parses a file (errors name it).
[[nodiscard]] InputScript load_input_script(const std::filesystem::path& path);
/// The text parse_input_script reads back to `frames` (identical consecutive frames merged).
[[nodiscard]] std::string format_input_script(std::span<const GameInput> frames);

} // namespace specula::games
