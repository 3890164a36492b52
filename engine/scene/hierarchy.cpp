#include "specula/scene/hierarchy.h"

#include "specula/core/error.h"
#include "specula/scene/components/name.h"
#include "specula/scene/components/parent.h"
#include "specula/scene/components/transform.h"
#include "specula/scene/components/world_transform.h"

#include <algorithm>
#include <charconv>
#include <limits>
#include <unordered_map>
#include <vector>

namespace specula {
namespace {

/// Marks, in the depth table, an entity on the chain being walked: meeting one again closes a
/// cycle. Real depths stay far below it (one per entity at most).
constexpr std::uint32_t kOnChain = std::numeric_limits<std::uint32_t>::max();

/// "parent chain forms a cycle: "a" -> "c" -> "b" -> "a"" for the cycle that `chain` (an
/// entity, its parent, ...) closes at `again`: from the entity created first (lowest slot), so
/// the message does not depend on where the walk entered the cycle.
std::string cycle_message(const ecs::Registry& registry, const std::vector<ecs::Entity>& chain,
                          ecs::Entity again) {
  std::vector<ecs::Entity> cycle(std::find(chain.begin(), chain.end(), again), chain.end());
  std::rotate(cycle.begin(),
              std::min_element(cycle.begin(), cycle.end(),
                               [](ecs::Entity a, ecs::Entity b) { return a.index < b.index; }),
              cycle.end());
  std::string message = "parent chain forms a cycle: ";
  for (const ecs::Entity e : cycle) message += entity_label(registry, e) + " -> ";
  return message + entity_label(registry, cycle.front());
}

std::string shortest(double v) {
  char buf[32];
  const auto result = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, result.ptr);
}

} // namespace

std::string format_position(const dvec3& p) {
  return "(" + shortest(p.x) + ", " + shortest(p.y) + ", " + shortest(p.z) + ")";
}

std::string entity_label(const ecs::Registry& registry, ecs::Entity e) {
  const Name* name = registry.try_get<Name>(e);
  if (name != nullptr && !name->value.empty()) return "\"" + name->value + "\"";
  return "entity " + std::to_string(e.index);
}

std::size_t update_world_transforms(ecs::Registry& registry, std::uint64_t tick,
                                    const std::string& context) {
  // Order entities so that every parent precedes its children: depth by walking up the chain
  // (memoised), then a counting sort by depth. O(n) for any hierarchy shape.
  std::vector<ecs::Entity> entities = registry.view<Transform>().entities();
  std::unordered_map<std::uint32_t, std::uint32_t> depth;
  depth.reserve(entities.size());
  std::uint32_t max_depth = 0;
  std::vector<ecs::Entity> chain;
  for (const ecs::Entity e : entities) {
    chain.clear();
    ecs::Entity cur = e;
    std::uint32_t base = 0;
    while (true) {
      if (auto it = depth.find(cur.index); it != depth.end()) {
        if (it->second == kOnChain) throw Error(context, cycle_message(registry, chain, cur));
        base = it->second + 1;
        break;
      }
      depth.emplace(cur.index, kOnChain);
      chain.push_back(cur);
      const Parent* parent = registry.try_get<Parent>(cur);
      if (parent == nullptr || parent->entity.is_null()) break;
      if (!registry.valid(parent->entity))
        throw Error(context, entity_label(registry, cur) + " has a parent that no longer exists");
      if (!registry.has<Transform>(parent->entity))
        throw Error(context, entity_label(registry, cur) + " has a parent without a transform");
      cur = parent->entity;
    }
    for (std::size_t i = chain.size(); i-- > 0;) {
      depth[chain[i].index] = base;
      max_depth = std::max(max_depth, base);
      ++base;
    }
  }
  std::vector<std::vector<ecs::Entity>> by_depth(std::size_t(max_depth) + 1);
  for (const ecs::Entity e : entities) by_depth[depth[e.index]].push_back(e);

  TransformChanges& changes = registry.resource_or_default<TransformChanges>();
  changes.moved.clear();
  ++changes.sequence;
  changes.tick = tick;
  std::size_t moved = 0;
  for (const auto& level : by_depth) {
    for (const ecs::Entity e : level) {
      dmat4 local = registry.get<Transform>(e).parent_from_local();
      if (registry.has<Hidden>(e)) // collapsed to its origin: hidden, and its subtree with it
        local = dmat4(dvec4(0.0), dvec4(0.0), dvec4(0.0), local[3]);
      dmat4 world = local;
      bool parent_moved = false;
      if (const Parent* parent = registry.try_get<Parent>(e);
          parent != nullptr && !parent->entity.is_null()) {
        const WorldTransform& pw = registry.get<WorldTransform>(parent->entity);
        world = pw.world_from_object * local;
        parent_moved = pw.moved && pw.moved_tick == tick;
      }
      // Composition (a parent's scale times a child's translation, an animated parent) can
      // carry a position out of the range every loader checks: an error here, not an abort in
      // a tracer.
      if (const dvec3 origin(world[3]); !in_range(origin))
        throw Error(context, entity_label(registry, e) + " is placed at " +
                                 format_position(origin) + ", outside " + kCoordinateRangeText);
      WorldTransform* wt = registry.try_get<WorldTransform>(e);
      if (wt == nullptr) {
        wt = &registry.emplace<WorldTransform>(e);
        wt->world_from_object = world;
        wt->moved = true;
        wt->moved_tick = tick;
        changes.moved.push_back(e);
        ++moved;
        continue;
      }
      const bool changed = parent_moved || wt->world_from_object != world;
      wt->moved = changed;
      if (changed) {
        wt->world_from_object = world;
        wt->moved_tick = tick;
        changes.moved.push_back(e);
        ++moved;
      }
    }
  }
  return moved;
}

} // namespace specula
