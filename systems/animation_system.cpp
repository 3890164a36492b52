#include "specula/systems/animation_system.h"

#include "specula/scene/animation_sampling.h"
#include "specula/scene/components/animation.h"
#include "specula/scene/components/camera.h"
#include "specula/scene/components/mesh.h"
#include "specula/scene/components/transform.h"

#include <vector>

namespace specula {

void animation_system(ecs::Registry& registry, const FrameContext& ctx) {
  const auto dt = static_cast<float>(ctx.dt);
  registry.view<Animation>().each([&](ecs::Entity e, Animation& anim) {
    anim.time = advance_time(anim.time, anim.speed, dt, anim.duration(), anim.loop);
    if (Transform* t = registry.try_get<Transform>(e)) {
      if (!anim.translation.empty()) t->translation = sample(anim.translation, anim.time);
      if (!anim.rotation.empty()) t->rotation = sample(anim.rotation, anim.time);
      if (!anim.scale.empty()) t->scale = sample(anim.scale, anim.time);
    }
    if (!anim.visibility.empty()) {
      const bool visible = visible_at(anim.visibility, anim.time);
      if (visible && registry.has<Hidden>(e)) registry.remove<Hidden>(e);
      if (!visible && !registry.has<Hidden>(e)) registry.emplace<Hidden>(e);
    }
    if (!anim.vertices.empty()) {
      Mesh* mesh = registry.try_get<Mesh>(e);
      // Vertices already sampled at this time (a paused or finished animation) are left alone,
      // tick included: nothing moved, so nothing is refitted.
      if (mesh != nullptr &&
          (mesh->deformed_positions.empty() || mesh->deformed_time != anim.time)) {
        sample(anim.vertices, anim.time, mesh->deformed_positions);
        if (anim.normals.empty())
          mesh->deformed_normals.clear();
        else
          sample_normals(anim.normals, anim.time, mesh->deformed_normals);
        mesh->deformed_time = anim.time;
        mesh->deformed_tick = ctx.tick;
      }
    }
  });
  // Hidden is the visibility switches' state: an entity whose switches are gone (its Animation
  // removed or replaced) is shown again.
  std::vector<ecs::Entity> shown;
  registry.view<Hidden>().each([&](ecs::Entity e, Hidden&) {
    const Animation* a = registry.try_get<Animation>(e);
    if (a == nullptr || a->visibility.empty()) shown.push_back(e);
  });
  for (const ecs::Entity e : shown) registry.remove<Hidden>(e);
  registry.view<CameraPath, Camera>().each([&](CameraPath& path, Camera& camera) {
    path.time = advance_time(path.time, 1.0f, dt, path.keys.back().time, path.loop);
    const CameraPath::Key key = sample(path, path.time);
    camera.position = key.position;
    camera.look_at = key.look_at;
    camera.up = key.up;
  });
}

} // namespace specula
