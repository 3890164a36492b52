#pragma once
#include "specula/ecs/entity.h"

namespace specula {

/// Places this entity's Transform in the parent's space. Cycles and stale parents are reported by
/// transform_system (specula::Error); scene loaders reject them up front.
struct Parent {
  ecs::Entity entity = ecs::null_entity;
};

} // namespace specula
