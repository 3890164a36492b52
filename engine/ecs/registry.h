#pragma once
/// \file
/// The registry: entities, their components, views over them, and per-world resources.
///
/// Rules (docs/ecs.md has the full list; tests/ecs tests each one):
/// 1. A handle is {index, generation}. destroy() bumps the generation: every copy of the handle
///    is then stale — valid() is false, has()/try_get() answer false/nullptr, get()/emplace()
///    on it are bugs (SPECULA_ASSERT). A recycled slot never revives an old handle.
/// 2. Component references stay valid when components of any type are added to any entity (pages
///    never move). Removing T from any entity may move one other T (the pool's last), so after a
///    remove<T> or destroy(), re-fetch T references you hold for other entities.
/// 3. view<A, B...>().each(f) walks the smallest of the pools backwards. Inside f you may:
///    - remove components from, or destroy, the entity being visited;
///    - add components (any type) to any entity, and create entities: entities that join the
///      view during the walk are not visited in this walk;
///    You may not remove viewed components from, or destroy, *other* entities that are still
///    ahead in the walk: collect them and do it after the walk.
/// 4. Resources are one value per type per registry (caches, shared geometry libraries), never
///    statics.

#include "core/assert.h"
#include "ecs/entity.h"
#include "ecs/storage.h"

#include <any>
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
  /// Calls f(entity, Ts&...) or f(Ts&...) for every entity with all of Ts (rule 3 above).
  template <typename F>
  void each(F&& f) {
    const PoolBase* lead = smallest();
    // Backwards over the lead pool: a removal at the current position swaps in an element that
    // was already visited, and entities added during the walk sit beyond the start position.
    for (std::size_t i = lead->size(); i-- > 0;) {
      if (i >= lead->size()) continue; // the walk's own removals shrank the pool
      const Entity e = lead->entities()[i];
      if (!(std::get<Pool<Ts>*>(pools_)->contains(e) && ...)) continue;
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
      if ((std::get<Pool<Ts>*>(pools_)->contains(e) && ...)) ++n;
    return n;
  }

  /// A snapshot of the entities in the view, in walk order.
  [[nodiscard]] std::vector<Entity> entities() const {
    std::vector<Entity> out;
    const auto lead = smallest()->entities();
    for (std::size_t i = lead.size(); i-- > 0;)
      if ((std::get<Pool<Ts>*>(pools_)->contains(lead[i]) && ...)) out.push_back(lead[i]);
    return out;
  }

private:
  friend class Registry;
  explicit View(Pool<Ts>*... pools) : pools_(pools...) {}

  [[nodiscard]] const PoolBase* smallest() const {
    const PoolBase* best = std::get<0>(pools_);
    ((best = std::get<Pool<Ts>*>(pools_)->size() < best->size() ? std::get<Pool<Ts>*>(pools_) : best),
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
  Registry(Registry&&) noexcept = default;
  Registry& operator=(Registry&&) noexcept = default;
  ~Registry() { clear(); }

  /// A new entity with no components. Reuses destroyed slots with a bumped generation.
  [[nodiscard]] Entity create() {
    if (!free_.empty()) {
      const std::uint32_t index = free_.back();
      free_.pop_back();
      ++alive_;
      return Entity{index, generations_[index]};
    }
    const auto index = static_cast<std::uint32_t>(generations_.size());
    SPECULA_ASSERT(index != null_entity.index);
    generations_.push_back(0);
    ++alive_;
    return Entity{index, 0};
  }

  /// Removes all of e's components and makes every handle to it stale. No-op on stale handles.
  void destroy(Entity e) {
    if (!valid(e)) return;
    for (auto& pool : pools_)
      if (pool) pool->remove(e);
    ++generations_[e.index];
    free_.push_back(e.index);
    --alive_;
  }

  [[nodiscard]] bool valid(Entity e) const {
    return e.index < generations_.size() && generations_[e.index] == e.generation &&
           !e.is_null();
  }
  /// Number of live entities.
  [[nodiscard]] std::size_t alive() const { return alive_; }

  /// Calls f(Entity) for every live entity, in slot order.
  template <typename F>
  void each_entity(F&& f) const {
    std::vector<bool> is_free(generations_.size(), false);
    for (const std::uint32_t i : free_) is_free[i] = true;
    for (std::uint32_t i = 0; i < generations_.size(); ++i)
      if (!is_free[i]) f(Entity{i, generations_[i]});
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
    if (p.contains(e)) return p.get(e) = T{std::forward<Args>(args)...};
    return p.emplace(e, std::forward<Args>(args)...);
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

  /// Destroys every entity and resource.
  void clear() {
    for (auto& pool : pools_)
      if (pool) pool->clear();
    generations_.clear();
    free_.clear();
    alive_ = 0;
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
  template <typename T>
  [[nodiscard]] T& resource() {
    T* r = try_resource<T>();
    SPECULA_ASSERT(r != nullptr);
    return *r;
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

  std::vector<std::unique_ptr<PoolBase>> pools_;
  std::vector<std::uint32_t> generations_;
  std::vector<std::uint32_t> free_;
  std::size_t alive_ = 0;
  std::vector<std::shared_ptr<void>> resources_;
};

} // namespace specula::ecs
