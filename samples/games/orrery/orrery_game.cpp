#include "orrery_game.h"

#include "../common/scene_kit.h"

#include <cmath>
#include <cstdio>
#include <limits>

namespace specula::games {

namespace {

Material matte(vec3 color) {
  Material m;
  m.base_color = color;
  return m;
}

/// Rotation by `a` radians about +y.
quat yaw(double a) { return glm::angleAxis(float(a), vec3(0, 1, 0)); }

/// The hidden beam waits under the floor.
constexpr dvec3 kBeamParked{0.0, -50.0, 0.0};

} // namespace

dvec3 Orrery::aim(double angle) { return {-std::sin(angle), 0.0, -std::cos(angle)}; }

Orrery::Orrery() {
  ecs::Registry& reg = registry_;
  using K = Kinematics::Type;
  add_mesh(reg, primitive("plane", 1, vec3(20, 1, 24)), at({0, 0, 2}), matte({0.35f, 0.3f, 0.28f}),
           K::Static);
  Material mirror = matte(vec3(0.9f));
  mirror.reflectivity = 0.85f;
  add_mesh(reg, primitive("box", 1, vec3(20, 5, 0.3f)), at({0, 2.5, -10}), mirror, K::Static);
  add_mesh(reg, primitive("box", 1, vec3(0.3f, 5, 24)), at({-10, 2.5, 2}), mirror, K::Static);

  Material sun = matte({1.0f, 0.8f, 0.3f});
  sun.emission = vec3(2.0f, 1.5f, 0.6f);
  bodies_.push_back({add_mesh(reg, primitive("sphere", 1.0f), at({0, kHeight, 0}), sun, K::Static),
                     1.0, false, false});
  add_mesh(reg, primitive("cylinder", 0.15f, vec3(1), kHeight), at({0, kHeight / 2, 0}),
           matte(vec3(0.5f)), K::Static);

  const double orbit[] = {3.0, 5.0, 7.5};
  const float size[] = {0.45f, 0.7f, 0.6f};
  const double omega[] = {1.1, 0.6, 0.35};
  const double phase[] = {0.3, 2.0, 4.1};
  const vec3 color[] = {{0.8f, 0.4f, 0.3f}, {0.3f, 0.5f, 0.9f}, {0.7f, 0.7f, 0.4f}};
  Material brass = matte({0.8f, 0.6f, 0.3f});
  brass.reflectivity = 0.4f;
  for (int i = 0; i < 3; ++i) {
    const ecs::Entity pivot = add_node(reg, at({0, kHeight, 0}), K::Hierarchical);
    pivots_.push_back({pivot, omega[i], phase[i]});
    add_mesh(reg, primitive("box", 1, vec3(float(orbit[i]), 0.06f, 0.06f)),
             at({orbit[i] / 2, 0, 0}), brass, K::Hierarchical, pivot);
    const ecs::Entity planet = add_mesh(reg, primitive("sphere", size[i]), at({orbit[i], 0, 0}),
                                        matte(color[i]), K::Hierarchical, pivot);
    bodies_.push_back({planet, size[i], true, true});
    if (i == 1) {
      const ecs::Entity moon_pivot = add_node(reg, at({0, 0, 0}), K::Hierarchical, planet);
      pivots_.push_back({moon_pivot, 2.5, 0.0});
      add_mesh(reg, primitive("box", 1, vec3(1.2f, 0.04f, 0.04f)), at({0.6, 0, 0}), brass,
               K::Hierarchical, moon_pivot);
      bodies_.push_back({add_mesh(reg, primitive("sphere", 0.22f), at({1.2, 0, 0}),
                                  matte(vec3(0.8f)), K::Hierarchical, moon_pivot),
                         0.22, true, false});
    }
  }

  turret_ = add_mesh(reg, primitive("box", 1, vec3(0.6f, 0.4f, 0.9f)), at(kTurret),
                     matte({0.3f, 0.8f, 0.4f}), K::Hierarchical);
  Material beam = matte({1.0f, 0.1f, 0.1f});
  beam.emission = vec3(4.0f, 0.3f, 0.3f);
  beam_ =
      add_mesh(reg, primitive("cylinder", 0.05f, vec3(1), 1.0f), at(kBeamParked), beam, K::Free);

  const ecs::Entity light = add_node(reg, at({0, 8, 6}), K::Static);
  Light l;
  l.intensity = 120.0f;
  reg.emplace<Light>(light, l);
  Camera c;
  c.position = dvec3(0, 9, 17);
  c.look_at = dvec3(0, 0, 0);
  c.vertical_fov = glm::radians(50.0f);
  reg.emplace<Camera>(reg.create(), c);
  turn_clockwork();
}

void Orrery::turn_clockwork() {
  for (const Pivot& p : pivots_) {
    registry_.get<Transform>(p.entity).rotation = yaw(p.phase + p.omega * time_);
  }
  registry_.get<Transform>(turret_).rotation = yaw(angle_);
}

void Orrery::fire() {
  ecs::Registry& reg = registry_;
  const dvec3 d = aim(angle_);
  Shot shot{time_, angle_, -1, false};
  double nearest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    const Aabb b = reg.get<Mesh>(bodies_[i].entity).geometry->bounds();
    const dvec3 c = dvec3(world_of(reg, bodies_[i].entity) * dvec4(dvec3(b.center()), 1.0));
    const dvec3 oc = c - kTurret;
    const double along = glm::dot(oc, d);
    const double miss2 = glm::dot(oc, oc) - along * along;
    const double r2 = bodies_[i].radius * bodies_[i].radius;
    if (along <= 0.0 || miss2 > r2) continue;
    const double t = along - std::sqrt(r2 - miss2);
    if (t < nearest) {
      nearest = t;
      shot.body = int(i);
    }
  }
  if (shot.body >= 0 && bodies_[std::size_t(shot.body)].target &&
      !bodies_[std::size_t(shot.body)].hit) {
    bodies_[std::size_t(shot.body)].hit = true;
    shot.scored = true;
    score_ += 100;
  } else {
    score_ = std::max<std::int64_t>(0, score_ - 10);
  }
  shots_.push_back(shot);
  last_shot_ = time_;
  bool all = true;
  for (const Body& b : bodies_) all = all && (!b.is_planet || b.hit);
  won_ = all;

  // Show the beam up to what it hit: a unit cylinder along +y, stretched and turned onto d.
  const double length = std::isfinite(nearest) ? nearest : 25.0;
  Transform& t = reg.get<Transform>(beam_);
  t.translation = kTurret + d * (length / 2);
  t.rotation = quat(vec3(0, 1, 0), vec3(d));
  t.scale = vec3(1.0f, float(length), 1.0f);
}

void Orrery::step(double dt, const GameInput& input) {
  time_ += dt;
  if (!won_) {
    if (input.held(Key::Left)) angle_ += kTurnRate * dt;
    if (input.held(Key::Right)) angle_ -= kTurnRate * dt;
    angle_ -= kMouseTurn * double(input.mouse_dx);
  }
  turn_clockwork();
  if (time_ - last_shot_ > kBeamShown) {
    Transform& t = registry_.get<Transform>(beam_);
    t = at(kBeamParked);
  }
  if (!won_ && input.was_pressed(Key::Space) && time_ - last_shot_ >= kCooldown) fire();
}

std::string Orrery::state_json() const {
  std::string hit;
  for (const Body& b : bodies_)
    hit += std::string(hit.empty() ? "" : ", ") + (b.hit ? "true" : "false");
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "\"score\": %lld, \"won\": %s, \"time\": %.9g, \"angle\": %.9g, \"shots\": %zu, "
                "\"bodies_hit\": [",
                static_cast<long long>(score_), won_ ? "true" : "false", time_, angle_,
                shots_.size());
  return buf + hit + "]";
}

std::string Orrery::hud_text() const {
  int planets = 0;
  for (const Body& b : bodies_) planets += b.is_planet && b.hit ? 1 : 0;
  char buf[160];
  std::snprintf(buf, sizeof buf, "%s  planets %d/3  shots %zu  score %lld",
                won_ ? "ALL HIT!" : "Orrery", planets, shots_.size(),
                static_cast<long long>(score_));
  return buf;
}

RenderJob Orrery::render_job(std::uint32_t width, std::uint32_t height) const {
  RenderJob job;
  job.settings.mode = TraceMode::Whitted;
  job.settings.max_depth = 5;
  job.settings.background = vec3(0.02f, 0.02f, 0.04f);
  job.image = Framebuffer(width, height);
  return job;
}

} // namespace specula::games
