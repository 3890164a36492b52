#pragma once
/// \file
/// PLACEHOLDER until the scene-rules branch lands: the kind of motion an entity has when its file
/// does not say.

#include "specula/ecs/registry.h"
#include "specula/scene/components/kinematics.h"

namespace specula {

/// Free when the entity has vertex animation; Hierarchical when its own or an ancestor's
/// animation moves it; else Static.
[[nodiscard]] Kinematics::Type inferred_kinematics(ecs::Registry& registry, ecs::Entity e);

} // namespace specula
