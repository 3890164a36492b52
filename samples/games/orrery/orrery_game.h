#pragma once
/// \file
/// Orrery: a clockwork solar system (pivots, arms, planets and a moon: a Parent hierarchy of
/// Hierarchical instances, turned by the game) in a room of mirrors. The player turns a beam
/// turret (left / right) and fires (space) to hit each planet once.
///
/// Rules (the tests recompute them):
/// - the turret at kTurret turns at kTurnRate rad/s while left / right is held, and by
///   kMouseTurn rad per pixel of horizontal mouse motion (rightwards turns right); angle 0 aims
///   along −z, positive turns left (towards −x); a shot needs kCooldown seconds since the
///   previous one;
/// - a shot is a ray in the floor plane at the planets' height; it hits the first body whose
///   bounding sphere (mesh bounds, world scale) it crosses: planets, the moon and the sun;
/// - a planet or the moon hit for the first time scores +100; a shot that scores nothing −10
///   (the score never goes below 0); the goal is every planet hit.

#include "../common/game.h"

#include <specula/core/math.h>

#include <vector>

namespace specula::games {

class Orrery final : public Game {
public:
  static constexpr double kHeight = 1.0; ///< the planets' and the beam's height
  static constexpr dvec3 kTurret{0.0, kHeight, 10.0};
  static constexpr double kTurnRate = 1.0;
  static constexpr double kMouseTurn = 0.004;
  static constexpr double kCooldown = 0.5;
  static constexpr double kBeamShown = 0.25; ///< seconds the beam stays visible

  struct Body {
    ecs::Entity entity;
    double radius;  ///< of its bounding sphere in world units
    bool target;    ///< scores when first hit (the sun does not)
    bool is_planet; ///< needed for the goal
    bool hit = false;
  };
  struct Shot {
    double time = 0.0;
    double angle = 0.0;
    int body = -1; ///< index into bodies(), -1 for none
    bool scored = false;
  };

  Orrery();

  void step(double dt, const GameInput& input) override;
  [[nodiscard]] bool won() const override { return won_; }
  [[nodiscard]] std::int64_t score() const override { return score_; }
  [[nodiscard]] std::string state_json() const override;
  [[nodiscard]] std::string hud_text() const override;
  [[nodiscard]] RenderJob render_job(std::uint32_t width, std::uint32_t height) const override;

  [[nodiscard]] double angle() const { return angle_; }
  [[nodiscard]] double time() const { return time_; }
  [[nodiscard]] const std::vector<Body>& bodies() const { return bodies_; }
  [[nodiscard]] const std::vector<Shot>& shots() const { return shots_; }
  /// The beam's direction at turret angle `angle`.
  [[nodiscard]] static dvec3 aim(double angle);

private:
  void turn_clockwork();
  void fire();

  struct Pivot {
    ecs::Entity entity;
    double omega, phase;
  };
  std::vector<Pivot> pivots_;
  std::vector<Body> bodies_;
  std::vector<Shot> shots_;
  ecs::Entity turret_, beam_;
  double angle_ = 0.0;
  double time_ = 0.0;
  double last_shot_ = -1e9;
  std::int64_t score_ = 0;
  bool won_ = false;
};

} // namespace specula::games
