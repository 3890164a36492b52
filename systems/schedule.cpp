#include "specula/systems/schedule.h"

#include "specula/systems/acceleration_system.h"
#include "specula/systems/animation_system.h"
#include "specula/systems/render_system.h"
#include "specula/systems/transform_system.h"

namespace specula {
namespace {

struct Stage {
  std::string_view name;
  void (*run)(ecs::Registry&, const FrameContext&);
};

constexpr Stage kStages[] = {
    {"animation", &animation_system},
    {"transform", &transform_system},
    {"acceleration", &acceleration_system},
    {"render", &render_system},
};

} // namespace

FrameContext Schedule::tick(ecs::Registry& registry, double dt) {
  ctx_.tick += 1;
  ctx_.dt = dt;
  ctx_.time += dt;
  for (const Stage& stage : kStages) stage.run(registry, ctx_);
  return ctx_;
}

std::vector<std::string_view> Schedule::system_names() {
  std::vector<std::string_view> names;
  for (const Stage& stage : kStages) names.push_back(stage.name);
  return names;
}

} // namespace specula
