#pragma once
/// \file
/// Sparse-set component storage. `dense` lists the entities that have the component, `sparse`
/// maps an entity's slot index to its position in `dense`; components sit in the same order as
/// `dense` in pages of fixed size, so adding a component never moves the others (references stay
/// valid across emplace). Removal swaps the last element into the hole (O(1)).

#include "specula/core/assert.h"
#include "specula/ecs/entity.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <span>
#include <type_traits>
#include <utility>
#include <vector>

namespace specula::ecs {

/// Builds a T from args the way the registry does everywhere: braces for aggregates (plain
/// structs need no constructor), parentheses otherwise, so that `std::vector<int>` from (3, 0)
/// means three zeros rather than the list {3, 0}.
template <typename T, typename... Args>
[[nodiscard]] T make_component(Args&&... args) {
  if constexpr (std::is_aggregate_v<T>)
    return T{std::forward<Args>(args)...};
  else
    return T(std::forward<Args>(args)...);
}

/// Type-erased part of a pool: membership and removal (what Registry::destroy needs).
class PoolBase {
public:
  static constexpr std::uint32_t kAbsent = 0xFFFFFFFFu;

  PoolBase() = default;
  PoolBase(const PoolBase&) = delete;
  PoolBase& operator=(const PoolBase&) = delete;
  virtual ~PoolBase() = default;

  /// Whether this exact handle (index and generation) has a component here.
  [[nodiscard]] bool contains(Entity e) const {
    return e.index < sparse_.size() && sparse_[e.index] != kAbsent && dense_[sparse_[e.index]] == e;
  }
  [[nodiscard]] std::size_t size() const { return dense_.size(); }
  [[nodiscard]] std::span<const Entity> entities() const { return dense_; }
  /// Position of e in entities(); e must be contained.
  [[nodiscard]] std::uint32_t position(Entity e) const {
    SPECULA_ASSERT(contains(e));
    return sparse_[e.index];
  }
  /// Removes e's component; returns false when e had none.
  virtual bool remove(Entity e) = 0;
  virtual void clear() = 0;

  /// Grows whenever the pool's membership changes (a component added or removed, the pool
  /// cleared) or a component is replaced or touched (Registry::emplace_or_replace, patch). Systems
  /// that mirror components elsewhere compare it with the value they saw last: equal means no
  /// entity gained, lost or announced a change of this component since. Edits made through a plain
  /// reference (Registry::get) are not seen: use Registry::patch for those.
  [[nodiscard]] std::uint64_t version() const { return version_; }
  /// Records a change of a component without membership change (see version()).
  void touch() { ++version_; }

protected:
  /// Makes room for e in sparse and one more entry in dense, so that insert_entity cannot throw
  /// once the component is constructed (a constructed component is never orphaned).
  void reserve_entity(Entity e) {
    if (e.index >= sparse_.size()) sparse_.resize(std::size_t(e.index) + 1, kAbsent);
    // Geometric growth by hand: reserve(size() + 1) would reallocate on every insertion.
    if (dense_.size() == dense_.capacity())
      dense_.reserve(std::max<std::size_t>(8, 2 * dense_.size()));
  }
  /// Appends e to dense; reserve_entity(e) must have been called.
  std::uint32_t insert_entity(Entity e) noexcept {
    ++version_;
    const auto pos = static_cast<std::uint32_t>(dense_.size());
    sparse_[e.index] = pos;
    dense_.push_back(e); // capacity reserved: no allocation, no throw
    return pos;
  }
  /// Swap-and-pop of e from dense (the last entity takes e's position).
  void erase_entity(Entity e) noexcept {
    ++version_;
    const std::uint32_t pos = sparse_[e.index];
    const Entity moved = dense_.back();
    dense_[pos] = moved;
    sparse_[moved.index] = pos;
    sparse_[e.index] = kAbsent;
    dense_.pop_back();
  }

  std::vector<std::uint32_t> sparse_;
  std::vector<Entity> dense_;
  std::uint64_t version_ = 0;
};

/// Storage for components of type T.
template <typename T>
class Pool final : public PoolBase {
public:
  static constexpr std::size_t kPageSize = 256;

  Pool() = default;
  ~Pool() override { clear(); }

  /// Constructs e's T from args (see make_component). e must not have one yet. If T's
  /// constructor throws, the pool is unchanged (it may keep a new empty page).
  template <typename... Args>
  T& emplace(Entity e, Args&&... args) {
    SPECULA_ASSERT(!e.is_null() && !contains(e));
    const auto pos = static_cast<std::uint32_t>(dense_.size());
    reserve_entity(e);
    if (pos / kPageSize >= pages_.size()) pages_.push_back(std::make_unique_for_overwrite<Page>());
    T* slot = ::new (storage(pos)) T(make_component<T>(std::forward<Args>(args)...));
    insert_entity(e);
    return *slot;
  }

  [[nodiscard]] T& get(Entity e) {
    SPECULA_ASSERT(contains(e));
    return *address(sparse_[e.index]);
  }
  [[nodiscard]] const T& get(Entity e) const {
    SPECULA_ASSERT(contains(e));
    return *address(sparse_[e.index]);
  }
  [[nodiscard]] T* try_get(Entity e) { return contains(e) ? address(sparse_[e.index]) : nullptr; }
  [[nodiscard]] const T* try_get(Entity e) const {
    return contains(e) ? address(sparse_[e.index]) : nullptr;
  }
  /// Component at position i of entities().
  [[nodiscard]] T& at(std::uint32_t i) {
    SPECULA_ASSERT(i < dense_.size());
    return *address(i);
  }

  /// Removes e's T by moving the last T into its place (that one T changes address; its value
  /// and owner are unchanged). Returns false when e has no T.
  bool remove(Entity e) override {
    if (!contains(e)) return false;
    const std::uint32_t pos = sparse_[e.index];
    const auto last = static_cast<std::uint32_t>(dense_.size() - 1);
    T* tail = address(last);
    // Move the data before touching membership: if the move assignment throws, e still owns
    // its (partly assigned) component and the last entity still owns its own.
    if (pos != last) *address(pos) = std::move(*tail);
    erase_entity(e);
    tail->~T(); // after erase, so a destructor that looks at the pool sees e's T gone
    return true;
  }

  /// Destroys every T (in position order).
  void clear() override {
    for (std::uint32_t i = 0; i < dense_.size(); ++i) address(i)->~T();
    for (const Entity e : dense_) sparse_[e.index] = kAbsent;
    if (!dense_.empty()) touch();
    dense_.clear();
  }

private:
  struct Page {
    alignas(T) std::byte bytes[sizeof(T) * kPageSize];
  };
  /// Raw storage of position i (no T need live there yet).
  [[nodiscard]] void* storage(std::uint32_t i) const {
    return pages_[i / kPageSize]->bytes + sizeof(T) * (i % kPageSize);
  }
  /// The live T at position i.
  [[nodiscard]] T* address(std::uint32_t i) const {
    return std::launder(static_cast<T*>(storage(i)));
  }

  std::vector<std::unique_ptr<Page>> pages_;
};

} // namespace specula::ecs
