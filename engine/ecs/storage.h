#pragma once
/// \file
/// Sparse-set component storage. `dense` lists the entities that have the component, `sparse`
/// maps an entity's slot index to its position in `dense`; components sit in the same order as
/// `dense` in pages of fixed size, so adding a component never moves the others (references stay
/// valid across emplace). Removal swaps the last element into the hole (O(1)).

#include "core/assert.h"
#include "ecs/entity.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <span>
#include <utility>
#include <vector>

namespace specula::ecs {

/// Type-erased part of a pool: membership and removal (what Registry::destroy needs).
class PoolBase {
public:
  static constexpr std::uint32_t kAbsent = 0xFFFFFFFFu;

  PoolBase() = default;
  PoolBase(const PoolBase&) = delete;
  PoolBase& operator=(const PoolBase&) = delete;
  virtual ~PoolBase() = default;

  [[nodiscard]] bool contains(Entity e) const {
    return e.index < sparse_.size() && sparse_[e.index] != kAbsent && dense_[sparse_[e.index]] == e;
  }
  [[nodiscard]] std::size_t size() const { return dense_.size(); }
  [[nodiscard]] std::span<const Entity> entities() const { return dense_; }
  /// Position of e in entities(); e must be contained.
  [[nodiscard]] std::uint32_t position(Entity e) const { return sparse_[e.index]; }
  /// Removes e's component; returns false when e had none.
  virtual bool remove(Entity e) = 0;
  virtual void clear() = 0;

protected:
  std::uint32_t insert_entity(Entity e) {
    if (e.index >= sparse_.size()) sparse_.resize(std::size_t(e.index) + 1, kAbsent);
    const auto pos = static_cast<std::uint32_t>(dense_.size());
    sparse_[e.index] = pos;
    dense_.push_back(e);
    return pos;
  }
  /// Swap-and-pop of e from dense; returns (removed position, last position) for the caller to
  /// move component data the same way.
  std::pair<std::uint32_t, std::uint32_t> erase_entity(Entity e) {
    const std::uint32_t pos = sparse_[e.index];
    const auto last = static_cast<std::uint32_t>(dense_.size() - 1);
    const Entity moved = dense_[last];
    dense_[pos] = moved;
    sparse_[moved.index] = pos;
    sparse_[e.index] = kAbsent;
    dense_.pop_back();
    return {pos, last};
  }

  std::vector<std::uint32_t> sparse_;
  std::vector<Entity> dense_;
};

/// Storage for components of type T.
template <typename T>
class Pool final : public PoolBase {
public:
  static constexpr std::size_t kPageSize = 256;

  ~Pool() override { clear(); }

  template <typename... Args>
  T& emplace(Entity e, Args&&... args) {
    SPECULA_ASSERT(!contains(e));
    const std::uint32_t pos = static_cast<std::uint32_t>(dense_.size());
    if (pos / kPageSize >= pages_.size()) pages_.push_back(std::make_unique<Page>());
    // Construct first: if T's constructor throws, the pool is unchanged.
    T* slot = ::new (static_cast<void*>(address(pos))) T{std::forward<Args>(args)...};
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
  [[nodiscard]] T& at(std::uint32_t i) { return *address(i); }

  bool remove(Entity e) override {
    if (!contains(e)) return false;
    const auto [pos, last] = erase_entity(e);
    T* hole = address(pos);
    T* tail = address(last);
    if (pos != last) *hole = std::move(*tail);
    tail->~T();
    return true;
  }

  void clear() override {
    for (std::uint32_t i = 0; i < dense_.size(); ++i) address(i)->~T();
    for (const Entity e : dense_) sparse_[e.index] = kAbsent;
    dense_.clear();
  }

private:
  struct Page {
    alignas(T) std::byte bytes[sizeof(T) * kPageSize];
  };
  [[nodiscard]] T* address(std::uint32_t i) const {
    return std::launder(reinterpret_cast<T*>(pages_[i / kPageSize]->bytes) + i % kPageSize);
  }

  std::vector<std::unique_ptr<Page>> pages_;
};

} // namespace specula::ecs
