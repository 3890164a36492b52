#pragma once
/// \file
/// Mirror Run: steer a mirror ball (arrows / WASD) down a lane past sliding blocks (Free) and a
/// spinning two-armed gate (a hub with two arms, Hierarchical), to the green goal.
///
/// Rules (the tests recompute them):
/// - the ball accelerates at kAccel towards the held directions, damped by exp(-kDamping·dt),
///   capped at kMaxSpeed; it stays on the floor (y = kPlayerRadius);
/// - it collides with every obstacle's box (its mesh bounds, placed by the obstacle's world
///   transform): pushed out to the box surface along the separation, the velocity's component
///   into the box reflected with restitution kRestitution; each contact that begins is a hit;
/// - reaching the goal sphere ends the run at time T:
///   score = max(0, 1000 − 50·hits − 10·⌊T⌋); before that, 0.
/// The ball carries a ray-cache cube: each move outdates its texels.

#include "../common/game.h"

#include <specula/core/math.h>

#include <vector>

namespace specula::games {

class MirrorRun final : public Game {
public:
  static constexpr double kPlayerRadius = 0.5;
  static constexpr double kAccel = 14.0;
  static constexpr double kDamping = 1.5;
  static constexpr double kMaxSpeed = 7.0;
  static constexpr double kRestitution = 0.5;
  static constexpr double kGoalRadius = 0.8;
  static constexpr dvec3 kGoal{0.0, 0.8, -34.0};

  /// Something the ball collides with: the entity, its mesh bounds, its world transform now.
  struct Obstacle {
    ecs::Entity entity;
    Aabb local;
    dmat4 world_from_object{1.0};
    bool in_contact = false;
  };

  MirrorRun();

  void step(double dt, const GameInput& input) override;
  [[nodiscard]] bool won() const override { return won_; }
  [[nodiscard]] std::int64_t score() const override;
  [[nodiscard]] std::string state_json() const override;
  [[nodiscard]] std::string hud_text() const override;
  [[nodiscard]] RenderJob render_job(std::uint32_t width, std::uint32_t height) const override;

  [[nodiscard]] const dvec3& position() const { return position_; }
  [[nodiscard]] const dvec3& velocity() const { return velocity_; }
  [[nodiscard]] int hits() const { return hits_; }
  [[nodiscard]] double time() const { return time_; }
  /// The run's time: until the goal, then frozen.
  [[nodiscard]] double run_time() const { return won_ ? finish_time_ : time_; }
  [[nodiscard]] ecs::Entity player() const { return player_; }
  [[nodiscard]] const std::vector<Obstacle>& obstacles() const { return obstacles_; }
  /// Puts the ball somewhere with a velocity (tests, a restart).
  void place_player(const dvec3& position, const dvec3& velocity);

private:
  void move_obstacles();
  void collide();
  void write_player();

  ecs::Entity player_, camera_;
  struct Slider {
    ecs::Entity entity;
    double z, amplitude, omega, phase;
  };
  std::vector<Slider> sliders_;
  ecs::Entity hub_;
  std::vector<ecs::Entity> arms_;
  std::vector<Obstacle> obstacles_;
  dvec3 position_{0.0, kPlayerRadius, 0.0};
  dvec3 velocity_{0.0};
  double time_ = 0.0;
  double finish_time_ = 0.0;
  int hits_ = 0;
  bool won_ = false;
};

} // namespace specula::games
