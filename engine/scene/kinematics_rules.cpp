#include "specula/scene/kinematics_rules.h"

#include "specula/scene/components/animation.h"
#include "specula/scene/components/parent.h"

namespace specula {

Kinematics::Type inferred_kinematics(ecs::Registry& registry, ecs::Entity e) {
  if (const Animation* a = registry.try_get<Animation>(e); a != nullptr && !a->vertices.empty())
    return Kinematics::Type::Free;
  std::size_t steps = 0;
  for (ecs::Entity cur = e; registry.valid(cur) && steps <= registry.alive(); ++steps) {
    if (const Animation* a = registry.try_get<Animation>(cur);
        a != nullptr && (!a->translation.empty() || !a->rotation.empty() || !a->scale.empty()))
      return Kinematics::Type::Hierarchical;
    const Parent* p = registry.try_get<Parent>(cur);
    if (p == nullptr) break;
    cur = p->entity;
  }
  return Kinematics::Type::Static;
}

} // namespace specula
