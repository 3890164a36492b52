#include "mirror_run_game.h"

#include "../common/scene_kit.h"

#include <cmath>
#include <cstdio>

namespace specula::games {

namespace {

Material matte(vec3 color) {
  Material m;
  m.base_color = color;
  return m;
}

} // namespace

MirrorRun::MirrorRun() {
  ecs::Registry& reg = registry_;
  using K = Kinematics::Type;
  add_mesh(reg, primitive("plane", 1, vec3(12, 1, 44)), at({0, 0, -16}),
           matte({0.55f, 0.55f, 0.6f}), K::Static);
  for (const double x : {-6.0, 6.0}) {
    obstacles_.push_back({add_mesh(reg, primitive("box", 1, vec3(1, 1.2f, 44)), at({x, 0.6, -16}),
                                   matte({0.6f, 0.3f, 0.25f}), K::Static),
                          {}});
  }
  const double slider_z[] = {-7.0, -14.0, -27.0};
  const double omega[] = {1.3, 1.7, 2.1};
  for (int i = 0; i < 3; ++i) {
    const ecs::Entity e = add_mesh(reg, primitive("box", 1, vec3(2.5f, 1, 1)),
                                   at({0, 0.5, slider_z[i]}), matte({0.9f, 0.6f, 0.1f}), K::Free);
    sliders_.push_back({e, slider_z[i], 3.2, omega[i], 2.0 * i});
    obstacles_.push_back({e, {}});
  }
  hub_ = add_mesh(reg, primitive("cylinder", 0.4f, vec3(1), 1.0f), at({0, 0.5, -20}),
                  matte({0.3f, 0.3f, 0.9f}), K::Hierarchical);
  obstacles_.push_back({hub_, {}});
  for (const double x : {-2.2, 2.2}) {
    const ecs::Entity arm =
        add_mesh(reg, primitive("box", 1, vec3(3.5f, 0.6f, 0.5f)), at({x, 0, 0}),
                 matte({0.4f, 0.4f, 1.0f}), K::Hierarchical, hub_);
    arms_.push_back(arm);
    obstacles_.push_back({arm, {}});
  }
  Material goal = matte({0.2f, 0.9f, 0.3f});
  goal.emission = vec3(0.3f, 1.2f, 0.4f);
  add_mesh(reg, primitive("sphere", float(kGoalRadius)), at(kGoal), goal, K::Static);
  Material mirror = matte(vec3(0.9f));
  mirror.reflectivity = 0.9f;
  obstacles_.push_back({add_mesh(reg, primitive("box", 1, vec3(12, 3, 0.3f)), at({0, 1.5, -37.5}),
                                 mirror, K::Static),
                        {}});

  Material ball = matte(vec3(0.9f));
  ball.reflectivity = 0.85f;
  player_ = add_mesh(reg, primitive("sphere", float(kPlayerRadius)), at(position_), ball, K::Free);
  reg.emplace<RayCacheCube>(player_, RayCacheCube{32});

  const ecs::Entity light = add_node(reg, at({0, 10, -14}), K::Static);
  Light l;
  l.intensity = 150.0f;
  reg.emplace<Light>(light, l);
  camera_ = reg.create();
  reg.emplace<Camera>(camera_, Camera{});

  for (Obstacle& o : obstacles_) o.local = reg.get<Mesh>(o.entity).geometry->bounds();
  move_obstacles();
  write_player();
}

void MirrorRun::place_player(const dvec3& position, const dvec3& velocity) {
  position_ = position;
  velocity_ = velocity;
  write_player();
}

void MirrorRun::move_obstacles() {
  ecs::Registry& reg = registry_;
  for (const Slider& s : sliders_) {
    reg.get<Transform>(s.entity).translation.x = s.amplitude * std::sin(s.omega * time_ + s.phase);
  }
  reg.get<Transform>(hub_).rotation = glm::angleAxis(float(0.9 * time_), vec3(0, 1, 0));
  for (Obstacle& o : obstacles_) o.world_from_object = world_of(reg, o.entity);
}

void MirrorRun::collide() {
  for (Obstacle& o : obstacles_) {
    bool inside = false;
    const dvec3 q = closest_on_box(o.world_from_object, o.local, position_, inside);
    // The ball rolls on the floor: separate in the floor's plane.
    dvec3 d = position_ - q;
    d.y = 0.0;
    const double dist = glm::length(d);
    const bool touching = inside || dist < kPlayerRadius;
    if (touching) {
      const dvec3 n = inside ? (dist > 0.0 ? -d / dist : dvec3(0, 0, 1)) : d / dist;
      position_ = dvec3(q.x, kPlayerRadius, q.z) + n * kPlayerRadius;
      const double vn = glm::dot(velocity_, n);
      if (vn < 0.0) velocity_ -= (1.0 + kRestitution) * vn * n;
      if (!o.in_contact) ++hits_;
    }
    o.in_contact = touching;
  }
}

void MirrorRun::write_player() {
  ecs::Registry& reg = registry_;
  reg.get<Transform>(player_).translation = position_;
  Camera& c = reg.get<Camera>(camera_);
  c.position = position_ + dvec3(0.0, 3.5, 6.0);
  c.look_at = position_ + dvec3(0.0, 0.0, -4.0);
  c.vertical_fov = glm::radians(55.0f);
}

void MirrorRun::step(double dt, const GameInput& input) {
  time_ += dt;
  move_obstacles();
  dvec3 push(0.0);
  if (!won_) {
    if (input.held(Key::Left)) push.x -= 1.0;
    if (input.held(Key::Right)) push.x += 1.0;
    if (input.held(Key::Up)) push.z -= 1.0;
    if (input.held(Key::Down)) push.z += 1.0;
  }
  if (push != dvec3(0.0)) velocity_ += kAccel * dt * glm::normalize(push);
  velocity_ *= std::exp(-kDamping * dt);
  if (const double speed = glm::length(velocity_); speed > kMaxSpeed)
    velocity_ *= kMaxSpeed / speed;
  position_ += velocity_ * dt;
  collide();
  if (!won_ && glm::length(position_ - dvec3(kGoal.x, kPlayerRadius, kGoal.z)) <
                   kPlayerRadius + kGoalRadius) {
    won_ = true;
    finish_time_ = time_;
  }
  write_player();
}

std::int64_t MirrorRun::score() const {
  if (!won_) return 0;
  return std::max<std::int64_t>(0, 1000 - 50 * std::int64_t(hits_) -
                                       10 * std::int64_t(std::floor(finish_time_)));
}

std::string MirrorRun::state_json() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "\"score\": %lld, \"won\": %s, \"hits\": %d, \"time\": %.9g, \"run_time\": %.9g, "
                "\"position\": [%.9g, %.9g, %.9g], \"velocity\": [%.9g, %.9g, %.9g]",
                static_cast<long long>(score()), won_ ? "true" : "false", hits_, time_, run_time(),
                position_.x, position_.y, position_.z, velocity_.x, velocity_.y, velocity_.z);
  return buf;
}

std::string MirrorRun::hud_text() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%s  time %.1f s  hits %d  score %lld",
                won_ ? "GOAL!" : "Mirror Run", run_time(), hits_, static_cast<long long>(score()));
  return buf;
}

RenderJob MirrorRun::render_job(std::uint32_t width, std::uint32_t height) const {
  RenderJob job;
  job.settings.mode = TraceMode::Whitted;
  job.settings.max_depth = 4;
  job.settings.background = vec3(0.05f, 0.06f, 0.1f);
  job.image = Framebuffer(width, height);
  job.cache.policy = cache::CachePolicy::On;
  return job;
}

} // namespace specula::games
