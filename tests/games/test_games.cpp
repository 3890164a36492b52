// The game samples: input files, the games' rules (recomputed here, from the engine's world
// transforms where they place things), and replays of the committed recordings through the
// headless front end, every frame rendered on the CPU.
#include "common/front_end.h"
#include "common/input_script.h"
#include "mirror_run/mirror_run_game.h"
#include "orrery/orrery_game.h"

#include <specula/core/error.h>
#include <specula/scene/components.h>
#include <specula/systems/schedule.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

namespace specula::games {
namespace {

const std::filesystem::path kGames = std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/games";

nlohmann::json read_json(const std::filesystem::path& path) {
  std::ifstream f(path);
  return nlohmann::json::parse(f);
}

std::filesystem::path temp_file(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         (name + "." + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "." +
          ::testing::UnitTest::GetInstance()->current_test_info()->name());
}

// --- Input files ---------------------------------------------------------------------------

TEST(InputScript, ParsesRangesKeysAndMouse) {
  const InputScript s = parse_input_script(
      "# comment\n2-3 down=up,left press=space  # trailing\n\n5 mouse=1.5,-2\n", "t.txt");
  ASSERT_EQ(s.frames.size(), 6u);
  EXPECT_EQ(s.at(0), GameInput{});
  for (const int f : {2, 3}) {
    EXPECT_TRUE(s.at(f).held(Key::Up) && s.at(f).held(Key::Left) && !s.at(f).held(Key::Right));
    EXPECT_TRUE(s.at(f).was_pressed(Key::Space));
  }
  EXPECT_EQ(s.at(4), GameInput{});
  EXPECT_EQ(s.at(5).mouse_dx, 1.5f);
  EXPECT_EQ(s.at(5).mouse_dy, -2.0f);
  EXPECT_EQ(s.at(1000), GameInput{}); // past the end: no input
}

TEST(InputScript, FormatParsesBackToTheSameFrames) {
  std::mt19937 rng(12);
  std::vector<GameInput> frames(400);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (i % 7 == 0) continue; // runs of empty frames are left out of the text
    frames[i].down = rng() % (1u << kKeyCount);
    frames[i].pressed = i % 5 == 0 ? rng() % (1u << kKeyCount) : 0;
    if (i % 11 == 0) frames[i].mouse_dx = float(rng() % 1000) / 7.0f;
    if (i > 0 && i % 3 == 0) frames[i] = frames[i - 1]; // runs merge into ranges
  }
  frames.back().down = 1; // the last frame is named
  const InputScript back = parse_input_script(format_input_script(frames), "round.txt");
  ASSERT_EQ(back.frames.size(), frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) EXPECT_EQ(back.frames[i], frames[i]) << i;
}

TEST(InputScript, ErrorsNameTheFileAndLine) {
  const std::pair<const char*, const char*> bad[] = {
      {"0 down=up\n\nx down=up\n", "bad.txt:3: expected FRAME"},
      {"5-2 down=up\n", "bad.txt:1: frame range ends before it starts"},
      {"0-4 down=up\n3 down=left\n", "bad.txt:2: frames must ascend"},
      {"1 down=jump\n", "bad.txt:1: unknown key 'jump'"},
      {"1 down=\n", "bad.txt:1: expected down=KEYS"},
      {"1 hold=up\n", "bad.txt:1: unknown field 'hold'"},
      {"1 mouse=1\n", "bad.txt:1: mouse needs two finite numbers"},
      {"1 mouse=nan,0\n", "bad.txt:1: mouse needs two finite numbers"},
      {"99999999999 down=up\n", "bad.txt:1: frame 99999999999 is beyond the limit"},
      {"1-99999999999999999999999 down=up\n", "bad.txt:1: expected FRAME"},
  };
  for (const auto& [text, expected] : bad) {
    try {
      (void)parse_input_script(text, "bad.txt");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos)
          << e.what() << " (expected " << expected << ")";
    }
  }
  EXPECT_THROW((void)load_input_script(kGames / "no_such_input.txt"), Error);
}

// --- Mirror Run ----------------------------------------------------------------------------

/// Steps and ticks (transforms only: rendering is not prepared) through `script`.
template <typename G, typename F>
void play(G& game, const InputScript& script, std::uint64_t frames, F&& after_tick) {
  Schedule schedule;
  for (std::uint64_t f = 0; f < frames; ++f) {
    game.step(kFrameDt, script.at(f));
    schedule.tick(game.registry(), kFrameDt);
    after_tick(f);
  }
}

TEST(Orrery, SameInputSameState) {
  const InputScript script = load_input_script(kGames / "orrery/demo_input.txt");
  Orrery a, b;
  play(a, script, 300, [](std::uint64_t) {});
  play(b, script, 300, [](std::uint64_t) {});
  EXPECT_EQ(a.state_json(), b.state_json());
  EXPECT_EQ(a.shots().size(), 4u);
}

TEST(MirrorRun, SameInputSameState) {
  const InputScript script = load_input_script(kGames / "mirror_run/demo_input.txt");
  MirrorRun a, b;
  play(a, script, 300, [](std::uint64_t) {});
  play(b, script, 300, [](std::uint64_t) {});
  EXPECT_EQ(a.state_json(), b.state_json());
  EXPECT_GT(a.hits(), 0); // the comparison covers collisions too
}

TEST(MirrorRun, BouncesOffAWallWithRestitution) {
  MirrorRun game;
  // Beside the right wall (inner face at x = 5.5) where no slider reaches, rolling into it.
  game.place_player({4.8, MirrorRun::kPlayerRadius, -3.0}, {6.0, 0.0, 0.0});
  const double inner_face = 6.0 - 0.5;
  bool bounced = false;
  for (int f = 0; f < 30 && !bounced; ++f) {
    const double vx = game.velocity().x * std::exp(-MirrorRun::kDamping * kFrameDt);
    game.step(kFrameDt, GameInput{});
    EXPECT_LE(game.position().x, inner_face - MirrorRun::kPlayerRadius + 1e-9) << "frame " << f;
    if (game.velocity().x < 0.0) {
      bounced = true;
      EXPECT_NEAR(game.velocity().x, -MirrorRun::kRestitution * vx, 1e-9);
      EXPECT_NEAR(game.position().x, inner_face - MirrorRun::kPlayerRadius, 1e-9);
    }
  }
  EXPECT_TRUE(bounced);
  EXPECT_EQ(game.hits(), 1);
  // Rolling away: the contact has ended, no further hit.
  for (int f = 0; f < 30; ++f) game.step(kFrameDt, GameInput{});
  EXPECT_EQ(game.hits(), 1);
  EXPECT_LT(game.position().x, inner_face - MirrorRun::kPlayerRadius - 0.1);
}

TEST(MirrorRun, NeverInsideAnObstacleAsTheEnginePlacesIt) {
  const InputScript script = load_input_script(kGames / "mirror_run/demo_input.txt");
  MirrorRun game;
  ecs::Registry& reg = game.registry();
  play(game, script, 600, [&](std::uint64_t f) {
    const dvec3 p = game.position();
    for (const MirrorRun::Obstacle& o : game.obstacles()) {
      // The obstacle as transform_system placed it (the arms through their hub).
      const dmat4& world = reg.get<WorldTransform>(o.entity).world_from_object;
      for (int c = 0; c < 4; ++c) {
        for (int r = 0; r < 4; ++r) ASSERT_NEAR(world[c][r], o.world_from_object[c][r], 1e-9);
      }
      // The ball's centre, in the box's frame, is at least its radius away (in the floor plane)
      // along the box's local x or z axes: a separating axis of the two.
      const dvec3 q = dvec3(glm::inverse(world) * dvec4(p, 1.0));
      const double sx = glm::length(dvec3(world[0])), sz = glm::length(dvec3(world[2]));
      const double gap_x = std::max(o.local.min.x - q.x, q.x - o.local.max.x) * sx;
      const double gap_z = std::max(o.local.min.z - q.z, q.z - o.local.max.z) * sz;
      ASSERT_GT(std::max(gap_x, gap_z), -1e-6) << "frame " << f << " inside an obstacle";
    }
  });
}

TEST(MirrorRun, StillBallServesItsCacheMovingOutdatesIt) {
  MirrorRun game;
  prepare_rendering(game.registry(), game.render_job(40, 24));
  Schedule schedule;
  const auto frame = [&] {
    schedule.tick(game.registry(), kFrameDt);
    return game.registry().resource<RenderJob>().last.cache;
  };
  // Not stepped: nothing moves, so after the first frames fill the cube its texels serve rays.
  for (int f = 0; f < 3; ++f) (void)frame();
  std::uint64_t hits = 0;
  for (int f = 0; f < 3; ++f) hits += frame().hits;
  EXPECT_GT(hits, 0u);
  EXPECT_EQ(frame().invalidated, 0u);
  game.place_player(game.position() + dvec3(1.0, 0.0, 0.0), dvec3(0.0));
  EXPECT_GT(frame().invalidated, 0u) << "moving the ball outdates its cube";
}

TEST(MirrorRun, ReplayReachesTheGoal) {
  const InputScript script = load_input_script(kGames / "mirror_run/demo_input.txt");
  MirrorRun game;
  HeadlessOptions options;
  options.frames = 600;
  options.width = 48;
  options.height = 27;
  options.stats = temp_file("mirror_run_stats.json");
  const HeadlessResult r = run_headless(game, "mirror_run", script, options);
  const nlohmann::json stats = read_json(*options.stats);
  std::filesystem::remove(*options.stats);
  EXPECT_EQ(r.nonfinite_frames, 0u);
  EXPECT_EQ(stats["frames"], 600);
  EXPECT_EQ(stats["nonfinite_frames"], 0);
  EXPECT_EQ(stats["nonfinite_samples"], 0);
  EXPECT_GT(stats["cache_texels_invalidated"].get<std::uint64_t>(), 0u) << "the ball moved";
  const nlohmann::json& state = stats["state"];
  ASSERT_TRUE(state["won"].get<bool>());
  const dvec3 p(state["position"][0], state["position"][1], state["position"][2]);
  // Reached means touched the goal; afterwards the ball keeps rolling (input ignored).
  EXPECT_LT(std::hypot(p.x - MirrorRun::kGoal.x, p.z - MirrorRun::kGoal.z), 4.0);
  const int hits = state["hits"];
  const double t = state["run_time"];
  EXPECT_GT(hits, 0);
  EXPECT_NEAR(t, 526 * kFrameDt, 1e-6) << "the recording reaches the goal in frame 525";
  EXPECT_EQ(state["score"].get<std::int64_t>(),
            std::max<std::int64_t>(0, 1000 - 50 * hits - 10 * std::int64_t(std::floor(t))));
}

// --- Orrery --------------------------------------------------------------------------------

/// The body a beam from the turret at `angle` meets first, from the bodies' world transforms.
int first_body_hit(ecs::Registry& reg, const Orrery& game, double angle) {
  const dvec3 d(-std::sin(angle), 0.0, -std::cos(angle));
  int best = -1;
  double nearest = 1e300;
  for (std::size_t i = 0; i < game.bodies().size(); ++i) {
    const Orrery::Body& b = game.bodies()[i];
    const dvec3 c = dvec3(reg.get<WorldTransform>(b.entity).world_from_object[3]);
    const dvec3 oc = c - Orrery::kTurret;
    const double along = glm::dot(oc, d);
    const double miss = glm::length(oc - along * d);
    if (along > 0.0 && miss <= b.radius && along < nearest) {
      nearest = along;
      best = int(i);
    }
  }
  return best;
}

TEST(Orrery, ReplayHitsEveryPlanetAndScoresByTheRules) {
  const InputScript script = load_input_script(kGames / "orrery/demo_input.txt");
  Orrery game;
  ecs::Registry& reg = game.registry();
  std::size_t seen = 0;
  std::int64_t score = 0;
  std::vector<bool> hit(game.bodies().size(), false);
  play(game, script, 300, [&](std::uint64_t f) {
    if (game.shots().size() == seen) return;
    ASSERT_EQ(game.shots().size(), seen + 1) << "frame " << f;
    const Orrery::Shot& shot = game.shots()[seen++];
    const int body = first_body_hit(reg, game, shot.angle);
    EXPECT_EQ(shot.body, body) << "frame " << f;
    const bool scores =
        body >= 0 && game.bodies()[std::size_t(body)].target && !hit[std::size_t(body)];
    if (scores) hit[std::size_t(body)] = true;
    score = scores ? score + 100 : std::max<std::int64_t>(0, score - 10);
  });
  EXPECT_TRUE(game.won());
  EXPECT_EQ(game.score(), score);
  EXPECT_EQ(game.shots().size(), 4u) << "four shots, the repeated presses inside the cooldown";
  EXPECT_EQ(score, 290) << "three planets, then one shot at the sun";
  for (const Orrery::Body& b : game.bodies()) EXPECT_TRUE(!b.is_planet || b.hit);
}

TEST(Orrery, KeysAndMouseTurnTheTurret) {
  Orrery game;
  GameInput left;
  left.set_down(Key::Left);
  for (int f = 0; f < 30; ++f) game.step(kFrameDt, left);
  EXPECT_NEAR(game.angle(), 30 * kFrameDt * Orrery::kTurnRate, 1e-12);
  GameInput mouse;
  mouse.mouse_dx = 100.0f; // rightwards: turns right
  game.step(kFrameDt, mouse);
  EXPECT_NEAR(game.angle(), 30 * kFrameDt * Orrery::kTurnRate - 100 * Orrery::kMouseTurn, 1e-12);
  // The turret entity turns with it: its -z axis is the beam's direction.
  Schedule schedule;
  schedule.tick(game.registry(), kFrameDt);
  dvec3 forward(0.0);
  game.registry().view<Transform, Mesh>().each([&](ecs::Entity e, const Transform& t, const Mesh&) {
    if (t.translation == Orrery::kTurret) {
      forward = -dvec3(game.registry().get<WorldTransform>(e).world_from_object[2]);
    }
  });
  EXPECT_NEAR(glm::length(forward - Orrery::aim(game.angle())), 0.0, 1e-6);
}

TEST(Orrery, CooldownBetweenShots) {
  Orrery game;
  GameInput fire;
  fire.set_pressed(Key::Space);
  for (int f = 0; f < 60; ++f) game.step(kFrameDt, fire);
  ASSERT_EQ(game.shots().size(), 2u);
  EXPECT_GE(game.shots()[1].time - game.shots()[0].time, Orrery::kCooldown - 1e-12);
}

TEST(Orrery, ReplayRendersFiniteFramesAndWritesTheStats) {
  const InputScript script = load_input_script(kGames / "orrery/demo_input.txt");
  Orrery game;
  HeadlessOptions options;
  options.frames = 300;
  options.width = 48;
  options.height = 27;
  options.stats = temp_file("orrery_stats.json");
  options.out = temp_file("orrery_frame.png");
  (void)run_headless(game, "orrery", script, options);
  const nlohmann::json stats = read_json(*options.stats);
  EXPECT_TRUE(std::filesystem::file_size(*options.out) > 0);
  std::filesystem::remove(*options.stats);
  std::filesystem::remove(*options.out);
  EXPECT_EQ(stats["nonfinite_frames"], 0);
  EXPECT_EQ(stats["nonfinite_samples"], 0);
  EXPECT_TRUE(stats["state"]["won"].get<bool>());
  EXPECT_EQ(stats["state"]["score"], game.score());
  EXPECT_EQ(stats["state"]["shots"], 4);
}

} // namespace
} // namespace specula::games
