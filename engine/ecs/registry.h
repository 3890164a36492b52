#pragma once
/// \file
/// The registry: entities, their components, views over them, and per-world resources.
///
/// Rules (docs/ecs.md states them in full; tests/ecs/test_ecs.cpp tests each one):
/// 1. A handle is {index, generation}. destroy() (and clear()) bumps the slot's generation: every
///    copy of the handle is then stale — valid() is false, has()/try_get()/remove() answer
///    false/nullptr/false, destroy() is a no-op, and get()/emplace()/emplace_or_replace() on it
///    are bugs (SPECULA_ASSERT). A recycled slot never revives an old handle: a slot whose
///    generation would wrap around is retired instead of recycled.
/// 2. Component references stay valid when components of any type are added to any entity (pages
///    never move). Removing T from any entity (remove<T>, destroy, clear) moves at most one other
///    T — the pool's last — keeping its value and owner; re-fetch T references you hold for other
///    entities after such a removal.
/// 3. view<A, B...>().each(f) first snapshots the entities in the view (walking the smallest of
///    the pools backwards), then calls f for each snapshotted entity that is still in the view
///    when its turn comes. So f may do anything to the registry: entities that join the view
///    during the walk are never visited; entities that leave it before their turn are skipped;
///    every other entity is visited exactly once. References f received dangle once f removes
///    that component from, or destroys, the visited entity.
/// 4. Resources are one value per type per registry (caches, shared geometry libraries), never
///    statics; clear() and the destructor destroy them after the components.
/// 5. Each pool has a version that grows on every membership change and on emplace_or_replace
///    and patch; edits through get() are invisible to it.

#include "specula/core/assert.h"
#include "specula/ecs/entity.h"
#include "specula/ecs/storage.h"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

namespace specula::ecs {

namespace detail {
inline std::size_t next_type_id() {
  static std::atomic<std::size_t> counter{0};
  return counter.fetch_add(1);
}
/// A dense small integer per type, shared by all registries of the process.
template <typename T>
std::size_t type_id() {
  static const std::size_t id = next_type_id();
  return id;
}
} // namespace detail

class Registry;

/// Entities that have all of Ts. Obtain with Registry::view<Ts...>().
template <typename... Ts>
class View {
  static_assert(sizeof...(Ts) > 0, "a view needs at least one component type");

public:
  /// Calls f(entity, Ts&...) or f(Ts&...) for every entity that has all of Ts when each() begins
  /// and still has them when its turn comes (rule 3). Costs one snapshot allocation per call.
  template <typename F>
  void each(F&& f) {
    // The snapshot is what makes the walk well-defined whatever f does: entities added during
    // the walk are not in it, and removals cannot shuffle unvisited entities out of reach (a
    // swap-and-pop inside a pool being walked directly would).
    const std::vector<Entity> walk = entities();
    for (const Entity e : walk) {
      if (!contains_all(e)) continue; // left the view (or was destroyed) earlier in the walk
      if constexpr (std::is_invocable_v<F, Entity, Ts&...>) {
        f(e, std::get<Pool<Ts>*>(pools_)->get(e)...);
      } else {
        static_assert(std::is_invocable_v<F, Ts&...>,
                      "each() takes f(Entity, Ts&...) or f(Ts&...)");
        f(std::get<Pool<Ts>*>(pools_)->get(e)...);
      }
    }
  }

  /// Number of entities in the view (walks the smallest pool).
  [[nodiscard]] std::size_t size() const {
    std::size_t n = 0;
    for (const Entity e : smallest()->entities())
      if (contains_all(e)) ++n;
    return n;
  }

  /// A snapshot of the entities in the view, in walk order (the smallest pool, backwards).
  [[nodiscard]] std::vector<Entity> entities() const {
    std::vector<Entity> out;
    const auto lead = smallest()->entities();
    out.reserve(lead.size());
    for (std::size_t i = lead.size(); i-- > 0;)
      if (contains_all(lead[i])) out.push_back(lead[i]);
    return out;
  }

private:
  friend class Registry;
  explicit View(Pool<Ts>*... pools) : pools_(pools...) {}

  [[nodiscard]] bool contains_all(Entity e) const {
    return (std::get<Pool<Ts>*>(pools_)->contains(e) && ...);
  }
  [[nodiscard]] const PoolBase* smallest() const {
    const PoolBase* best = std::get<0>(pools_);
    ((best =
          std::get<Pool<Ts>*>(pools_)->size() < best->size() ? std::get<Pool<Ts>*>(pools_) : best),
     ...);
    return best;
  }

  std::tuple<Pool<Ts>*...> pools_;
};

class Registry {
public:
  Registry() = default;
  Registry(const Registry&) = delete;
  Registry& operator=(const Registry&) = delete;
  /// The moved-from registry is empty (no entities, pools or resources) and usable.
  Registry(Registry&& other) noexcept
      : pools_(std::exchange(other.pools_, {})), slots_(std::exchange(other.slots_, {})),
        free_(std::exchange(other.free_, {})), alive_(std::exchange(other.alive_, 0)),
        resources_(std::exchange(other.resources_, {})) {}
  /// Destroys this registry's entities and resources first; `other` is left empty.
  Registry& operator=(Registry&& other) noexcept {
    if (this != &other) {
      clear();
      pools_ = std::exchange(other.pools_, {});
      slots_ = std::exchange(other.slots_, {});
      free_ = std::exchange(other.free_, {});
      alive_ = std::exchange(other.alive_, 0);
      resources_ = std::exchange(other.resources_, {});
    }
    return *this;
  }
  ~Registry() { clear(); }

  /// A new entity with no components. Reuses a destroyed slot (most recently freed first) under
  /// its bumped generation, so the new handle differs from every handle the slot had before.
  [[nodiscard]] Entity create() {
    if (!free_.empty()) {
      const std::uint32_t index = free_.back();
      free_.pop_back();
      slots_[index].live = true;
      ++alive_;
      return Entity{index, slots_[index].generation};
    }
    const auto index = static_cast<std::uint32_t>(slots_.size());
    SPECULA_ASSERT(index != null_entity.index);
    slots_.push_back(Slot{0, true});
    ++alive_;
    return Entity{index, 0};
  }

  /// Removes all of e's components and makes every handle to it stale. No-op on stale handles.
  void destroy(Entity e) {
    if (!valid(e)) return;
    // By index: a component destructor may create pools of new types, growing pools_.
    for (std::size_t i = 0; i < pools_.size(); ++i)
      if (pools_[i]) pools_[i]->remove(e);
    release_slot(e.index);
  }

  /// Whether e names a live entity (false for null_entity and stale handles).
  [[nodiscard]] bool valid(Entity e) const {
    return e.index < slots_.size() && slots_[e.index].live &&
           slots_[e.index].generation == e.generation;
  }
  /// Number of live entities.
  [[nodiscard]] std::size_t alive() const { return alive_; }

  /// Calls f(Entity) for every entity live when the call begins and still live when its turn
  /// comes, in slot order; entities created by f are not visited.
  template <typename F>
  void each_entity(F&& f) const {
    std::vector<Entity> walk;
    walk.reserve(alive_);
    for (std::uint32_t i = 0; i < slots_.size(); ++i)
      if (slots_[i].live) walk.push_back(Entity{i, slots_[i].generation});
    for (const Entity e : walk)
      if (valid(e)) f(e);
  }

  template <typename T, typename... Args>
  T& emplace(Entity e, Args&&... args) {
    SPECULA_ASSERT(valid(e));
    return pool<T>().emplace(e, std::forward<Args>(args)...);
  }
  template <typename T, typename... Args>
  T& emplace_or_replace(Entity e, Args&&... args) {
    SPECULA_ASSERT(valid(e));
    Pool<T>& p = pool<T>();
    if (p.contains(e)) {
      p.touch();
      return p.get(e) = make_component<T>(std::forward<Args>(args)...);
    }
    return p.emplace(e, std::forward<Args>(args)...);
  }
  /// Calls f(T&) on e's T and records the change (version<T>() grows), so systems that mirror T
  /// elsewhere (the scene layer's material and mesh tables) pick it up. Edits made through get()
  /// are not recorded. e must have a T.
  template <typename T, typename F>
  T& patch(Entity e, F&& f) {
    Pool<T>& p = pool<T>();
    T& component = get<T>(e);
    f(component);
    p.touch();
    return component;
  }
  /// The version of T's pool (PoolBase::version): grows on every membership change of T and every
  /// emplace_or_replace/patch of a T. 0 while no T was ever added.
  template <typename T>
  [[nodiscard]] std::uint64_t version() const {
    const std::size_t id = detail::type_id<T>();
    return id < pools_.size() && pools_[id] ? pools_[id]->version() : 0;
  }
  /// Removes T from e; returns whether it had one (false for stale handles).
  template <typename T>
  bool remove(Entity e) {
    return valid(e) && pool<T>().remove(e);
  }
  /// Whether e is live and has all of Ts.
  template <typename... Ts>
  [[nodiscard]] bool has(Entity e) const {
    return valid(e) && (contains<Ts>(e) && ...);
  }
  template <typename T>
  [[nodiscard]] T& get(Entity e) {
    SPECULA_ASSERT(valid(e));
    return pool<T>().get(e);
  }
  template <typename T>
  [[nodiscard]] const T& get(Entity e) const {
    SPECULA_ASSERT(valid(e) && contains<T>(e));
    return static_cast<const Pool<T>*>(pools_[detail::type_id<T>()].get())->get(e);
  }
  /// e's T, or nullptr when e is stale or has none.
  template <typename T>
  [[nodiscard]] T* try_get(Entity e) {
    return valid(e) ? pool<T>().try_get(e) : nullptr;
  }
  template <typename T>
  [[nodiscard]] const T* try_get(Entity e) const {
    if (!valid(e) || !contains<T>(e)) return nullptr;
    return &get<T>(e);
  }
  /// Number of entities with a T.
  template <typename T>
  [[nodiscard]] std::size_t count() const {
    const std::size_t id = detail::type_id<T>();
    return id < pools_.size() && pools_[id] ? pools_[id]->size() : 0;
  }

  template <typename... Ts>
  [[nodiscard]] View<Ts...> view() {
    return View<Ts...>(&pool<Ts>()...);
  }

  /// Destroys every entity (every handle becomes stale, as with destroy()), then every resource.
  /// Pools stay allocated, so views taken before remain usable (and empty).
  void clear() {
    for (std::size_t i = 0; i < pools_.size(); ++i)
      if (pools_[i]) pools_[i]->clear();
    // Keep the generations: resetting them would let create() hand out handles equal to old ones.
    for (std::uint32_t i = 0; i < slots_.size(); ++i)
      if (slots_[i].live) release_slot(i);
    resources_.clear();
  }

  // --- Resources: one value per type per registry (rule 4). ---
  template <typename T, typename... Args>
  T& set_resource(Args&&... args) {
    const std::size_t id = detail::type_id<T>();
    if (id >= resources_.size()) resources_.resize(id + 1);
    resources_[id] = std::make_shared<T>(std::forward<Args>(args)...);
    return *std::static_pointer_cast<T>(resources_[id]);
  }
  template <typename T>
  [[nodiscard]] T* try_resource() {
    const std::size_t id = detail::type_id<T>();
    return id < resources_.size() ? static_cast<T*>(resources_[id].get()) : nullptr;
  }
  template <typename T>
  [[nodiscard]] const T* try_resource() const {
    const std::size_t id = detail::type_id<T>();
    return id < resources_.size() ? static_cast<const T*>(resources_[id].get()) : nullptr;
  }
  /// The T resource, which must exist (SPECULA_ASSERT).
  template <typename T>
  [[nodiscard]] T& resource() {
    const std::size_t id = detail::type_id<T>();
    // Indexing directly, not through try_resource: with assertions off, a null branch inlined
    // into callers trips -Wnull-dereference.
    SPECULA_ASSERT(id < resources_.size() && resources_[id] != nullptr);
    return *static_cast<T*>(resources_[id].get());
  }
  template <typename T>
  [[nodiscard]] T& resource_or_default() {
    T* r = try_resource<T>();
    return r ? *r : set_resource<T>();
  }

private:
  template <typename T>
  Pool<T>& pool() {
    const std::size_t id = detail::type_id<T>();
    if (id >= pools_.size()) pools_.resize(id + 1);
    if (!pools_[id]) pools_[id] = std::make_unique<Pool<T>>();
    return *static_cast<Pool<T>*>(pools_[id].get());
  }
  template <typename T>
  [[nodiscard]] bool contains(Entity e) const {
    const std::size_t id = detail::type_id<T>();
    return id < pools_.size() && pools_[id] && pools_[id]->contains(e);
  }

  /// Marks a live slot dead and bumps its generation, making its handles stale. A slot at the
  /// last generation is retired (never handed out again): bumping would wrap to 0 and revive
  /// the slot's oldest handles.
  void release_slot(std::uint32_t index) {
    Slot& slot = slots_[index];
    SPECULA_ASSERT(slot.live);
    slot.live = false;
    --alive_;
    if (slot.generation == kLastGeneration) return;
    ++slot.generation;
    free_.push_back(index);
  }

  static constexpr std::uint32_t kLastGeneration = 0xFFFFFFFFu;
  struct Slot {
    std::uint32_t generation = 0;
    bool live = false;
  };

  std::vector<std::unique_ptr<PoolBase>> pools_;
  std::vector<Slot> slots_;
  /// Dead, non-retired slots; create() takes from the back.
  std::vector<std::uint32_t> free_;
  std::size_t alive_ = 0;
  std::vector<std::shared_ptr<void>> resources_;
};

} // namespace specula::ecs
