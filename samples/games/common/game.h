#pragma once
/// \file
/// What the game samples share: the input a game reads each frame, and the interface the front
/// ends (headless replay, window) drive. A game is pure state advanced by step(dt, input); it
/// owns the registry holding the scene entities it drives, and renders only through the
/// engine's schedule.

#include <specula/ecs/registry.h>
#include <specula/render/render_job.h>

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace specula::games {

/// The keys the games use (the window maps arrows and WASD onto the four directions).
enum class Key : std::uint8_t { Left, Right, Up, Down, Space };
inline constexpr int kKeyCount = 5;

[[nodiscard]] std::optional<Key> parse_key(std::string_view name);
[[nodiscard]] const char* key_name(Key key);

/// One frame's input: keys held, keys that went down this frame, mouse motion in pixels.
struct GameInput {
  std::uint32_t down = 0;    ///< bit per Key
  std::uint32_t pressed = 0; ///< bit per Key
  float mouse_dx = 0.0f;
  float mouse_dy = 0.0f;

  [[nodiscard]] bool held(Key k) const { return (down >> unsigned(k)) & 1u; }
  [[nodiscard]] bool was_pressed(Key k) const { return (pressed >> unsigned(k)) & 1u; }
  void set_down(Key k) { down |= 1u << unsigned(k); }
  void set_pressed(Key k) { pressed |= 1u << unsigned(k); }
  friend bool operator==(const GameInput&, const GameInput&) = default;
};

class Game {
public:
  Game() = default;
  Game(const Game&) = delete;
  Game& operator=(const Game&) = delete;
  virtual ~Game() = default;

  /// Advances the game by dt seconds: moves what it drives (writing Transforms), handles
  /// collisions and the rules. Rendering is the schedule's, run by the front end afterwards.
  virtual void step(double dt, const GameInput& input) = 0;
  /// The goal is reached (the game then ignores input; the world keeps moving).
  [[nodiscard]] virtual bool won() const = 0;
  [[nodiscard]] virtual std::int64_t score() const = 0;
  /// The state as the members of a JSON object (no braces), for the stats file.
  [[nodiscard]] virtual std::string state_json() const = 0;
  /// One line for the window's HUD.
  [[nodiscard]] virtual std::string hud_text() const = 0;
  /// How the game renders (mode, depth, caches) into a width × height image.
  [[nodiscard]] virtual RenderJob render_job(std::uint32_t width, std::uint32_t height) const = 0;

  [[nodiscard]] ecs::Registry& registry() { return registry_; }

protected:
  ecs::Registry registry_;
};

} // namespace specula::games
