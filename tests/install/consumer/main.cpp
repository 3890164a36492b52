// Uses only installed headers: builds a world, ticks the schedule, checks the result.
#include <specula/scene/components.h>
#include <specula/systems/schedule.h>

#include <cstdio>

int main() {
  specula::ecs::Registry registry;
  const auto parent = registry.create();
  const auto child = registry.create();
  specula::Transform t;
  t.translation = specula::vec3(1, 2, 3);
  registry.emplace<specula::Transform>(parent, t);
  registry.emplace<specula::Transform>(child, t);
  registry.emplace<specula::Parent>(child, specula::Parent{parent});
  specula::Schedule schedule;
  schedule.tick(registry, 1.0 / 60.0);
  const float x = registry.get<specula::WorldTransform>(child).world_from_object[3].x;
  std::printf("child world x = %g\n", double(x));
  return x == 2.0f ? 0 : 1;
}
