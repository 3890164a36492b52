#pragma once
/// \file
/// Entity handles: a 32-bit slot index plus a 32-bit generation. Destroying an entity bumps its
/// slot's generation, so every handle to it becomes detectably stale (Registry::valid is false).

#include <cstdint>
#include <functional>

namespace specula::ecs {

struct Entity {
  std::uint32_t index = 0xFFFFFFFFu;
  std::uint32_t generation = 0;

  friend constexpr bool operator==(Entity, Entity) = default;
  [[nodiscard]] constexpr bool is_null() const { return index == 0xFFFFFFFFu; }
};

/// The handle that never names an entity.
inline constexpr Entity null_entity{};

} // namespace specula::ecs

template <>
struct std::hash<specula::ecs::Entity> {
  std::size_t operator()(specula::ecs::Entity e) const noexcept {
    return std::hash<std::uint64_t>{}((std::uint64_t(e.generation) << 32) | e.index);
  }
};
