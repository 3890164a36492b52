#include "specula/scene/kinematics_rules.h"

#include "specula/core/error.h"
#include "specula/scene/components/animation.h"
#include "specula/scene/components/mesh.h"
#include "specula/scene/components/parent.h"
#include "specula/scene/hierarchy.h"

#include <algorithm>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace specula {
namespace {

/// Whether e's own Animation moves it: any translation, rotation or scale track, or visibility
/// switches (hiding collapses its world transform).
bool animates_transform(const ecs::Registry& registry, ecs::Entity e) {
  const Animation* a = registry.try_get<Animation>(e);
  return a != nullptr && (!a->translation.empty() || !a->rotation.empty() || !a->scale.empty() ||
                          !a->visibility.empty());
}

bool deforms(const ecs::Registry& registry, ecs::Entity e) {
  const Animation* a = registry.try_get<Animation>(e);
  return a != nullptr && !a->vertices.empty();
}

/// For an entity, the nearest entity on its Parent chain, itself first, whose Animation moves it
/// (null when none). Answers are memoised by slot for every entity a walk passes, so asking for
/// every entity of a registry costs O(n) whatever the hierarchy's shape (a 100k-deep chain too).
/// The registry must not change between calls.
class Movers {
public:
  explicit Movers(const ecs::Registry& registry) : registry_(registry) {}

  [[nodiscard]] ecs::Entity of(ecs::Entity e) {
    walk_.clear();
    ecs::Entity mover = ecs::null_entity;
    // A cycle never meets a memoised entity nor an end; it stops once the walk is longer than
    // the registry has entities.
    const std::size_t limit = registry_.alive();
    for (ecs::Entity cur = e;;) {
      if (const auto it = memo_.find(cur.index); it != memo_.end()) {
        mover = it->second;
        break;
      }
      walk_.push_back(cur);
      if (animates_transform(registry_, cur)) {
        mover = cur;
        break;
      }
      const Parent* parent = registry_.try_get<Parent>(cur);
      if (parent == nullptr || !registry_.valid(parent->entity) || walk_.size() > limit) break;
      cur = parent->entity;
    }
    for (const ecs::Entity w : walk_) memo_[w.index] = mover;
    return mover;
  }

private:
  const ecs::Registry& registry_;
  std::unordered_map<std::uint32_t, ecs::Entity> memo_;
  std::vector<ecs::Entity> walk_;
};

/// The entities of a view in slot (= creation, = file) order, so the first bad entity of a file
/// is the one reported.
std::vector<ecs::Entity> in_slot_order(std::vector<ecs::Entity> entities) {
  std::sort(entities.begin(), entities.end(),
            [](ecs::Entity a, ecs::Entity b) { return a.index < b.index; });
  return entities;
}

} // namespace

Kinematics::Type inferred_kinematics(const ecs::Registry& registry, ecs::Entity e) {
  if (deforms(registry, e)) return Kinematics::Type::Free;
  // Allocation-free, for callers that ask per entity (accelerators); settle_kinematics memoises
  // the same walk (Movers).
  const std::size_t limit = registry.alive();
  ecs::Entity cur = e;
  for (std::size_t steps = 0; steps <= limit; ++steps) {
    if (animates_transform(registry, cur)) return Kinematics::Type::Hierarchical;
    const Parent* parent = registry.try_get<Parent>(cur);
    if (parent == nullptr || !registry.valid(parent->entity)) break;
    cur = parent->entity;
  }
  return Kinematics::Type::Static;
}

const char* kinematics_name(Kinematics::Type type) {
  switch (type) {
  case Kinematics::Type::Static:
    return "static";
  case Kinematics::Type::Hierarchical:
    return "hierarchical";
  case Kinematics::Type::Free:
    return "free";
  }
  return "static";
}

void settle_kinematics(ecs::Registry& registry, const std::string& source) {
  Movers movers(registry);
  for (const ecs::Entity e : in_slot_order(registry.view<Kinematics>().entities())) {
    const Kinematics::Type stated = registry.get<Kinematics>(e).type;
    const auto claim = [&] {
      return "kinematics of " + entity_label(registry, e) + " is \"" + kinematics_name(stated) +
             "\"";
    };
    if (stated != Kinematics::Type::Free && deforms(registry, e))
      throw Error(source, claim() + " but its vertex animation deforms its mesh: use \"free\"");
    if (stated != Kinematics::Type::Static) continue;
    const ecs::Entity mover = movers.of(e);
    if (mover.is_null()) continue;
    throw Error(source, claim() + " but it is moved by " +
                            (mover == e ? std::string("its own animation")
                                        : "the animation of its ancestor " +
                                              entity_label(registry, mover)) +
                            ": use \"hierarchical\" or \"free\"");
  }
  for (const ecs::Entity e : in_slot_order(registry.view<Mesh>().entities())) {
    if (registry.has<Kinematics>(e)) continue;
    Kinematics::Type type = Kinematics::Type::Static;
    if (deforms(registry, e)) {
      type = Kinematics::Type::Free;
    } else if (!movers.of(e).is_null()) {
      type = Kinematics::Type::Hierarchical;
    }
    registry.emplace<Kinematics>(e, Kinematics{type});
  }
}

} // namespace specula
