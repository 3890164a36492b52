#pragma once
#include "specula/ecs/entity.h"

namespace specula {

/// Places this entity's Transform in the parent's space. Cycles and stale parents are reported by
/// update_world_transforms (specula::Error), which load_scene runs once after loading and
/// transform_system every tick.
struct Parent {
  ecs::Entity entity = ecs::null_entity;
};

} // namespace specula
