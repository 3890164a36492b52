#include "specula/systems/schedule.h"

#include "specula/render/render_job.h"
#include "specula/systems/acceleration_system.h"
#include "specula/systems/animation_system.h"
#include "specula/systems/cache_invalidation_system.h"
#include "specula/systems/render_system.h"
#include "specula/systems/scene_layer_system.h"
#include "specula/systems/transform_system.h"

#include <chrono>
#include <iterator>

namespace specula {
namespace {

struct Stage {
  std::string_view name;
  void (*run)(ecs::Registry&, const FrameContext&);
};

constexpr Stage kStages[] = {
    {"animation", &animation_system},     {"transform", &transform_system},
    {"scene_layer", &scene_layer_system}, {"acceleration", &acceleration_system},
    {"cache_invalidation", &cache_invalidation_system}, {"render", &render_system},
};

static_assert(std::size(kStages) == 6, "SystemTimes names one field per stage");

} // namespace

FrameContext Schedule::tick(ecs::Registry& registry, double dt) {
  using Clock = std::chrono::steady_clock;
  ctx_.tick += 1;
  ctx_.dt = dt;
  ctx_.time += dt;
  FrameTimings timings;
  const Clock::time_point start = Clock::now();
  Clock::time_point stage_start = start;
  for (const Stage& stage : kStages) {
    stage.run(registry, ctx_);
    const Clock::time_point now = Clock::now();
    timings.system_ms.push_back(
        std::chrono::duration<double, std::milli>(now - stage_start).count());
    stage_start = now;
  }
  timings.ms = std::chrono::duration<double, std::milli>(stage_start - start).count();
  if (RenderJob* job = registry.try_resource<RenderJob>()) {
    job->last.ms = timings.ms;
    job->last.time = ctx_.time;
    // kStages' order (the static_assert beside kStages keeps the two in step).
    SystemTimes& t = job->last.systems;
    t.animation_ms = timings.system_ms[0];
    t.transform_ms = timings.system_ms[1];
    t.scene_layer_ms = timings.system_ms[2];
    t.acceleration_ms = timings.system_ms[3];
    t.cache_invalidation_ms = timings.system_ms[4];
    t.render_ms = timings.system_ms[5];
  }
  registry.resource_or_default<FrameTimings>() = std::move(timings); // no new resource per tick
  return ctx_;
}

std::vector<std::string_view> Schedule::system_names() {
  std::vector<std::string_view> names;
  for (const Stage& stage : kStages) names.push_back(stage.name);
  return names;
}

} // namespace specula
