#pragma once
/// \file
/// The one place that maps a backend name to a tracer. Backends are chosen once, at start-up, by
/// name or by capability (`auto`); nothing else in the engine names a backend type.

#include "specula/ecs/registry.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace specula {

struct BackendInfo {
  std::string_view name;
  bool available = false; ///< in this build and usable on this machine
  std::string reason;     ///< why not, when not available
  /// Whether rays through shared edges and vertices of closed meshes never slip between the
  /// triangles (a watertight ray/triangle test and conservative traversal). Embree 3's robust
  /// mode comes close but is not: the conformance suite measures how close
  /// (docs/design/watertightness.md).
  bool watertight = false;
};

/// Every backend name `--backend` accepts besides `auto`, in the order `auto` prefers them
/// (a real GPU first, then the CPU backends), with their availability.
[[nodiscard]] std::vector<BackendInfo> backends();

/// The entry of backends() with this name; throws specula::Error for a name no build knows.
[[nodiscard]] BackendInfo backend_info(std::string_view name);

/// Whether `name` is `auto` or a backend name any build knows (available here or not).
[[nodiscard]] bool is_backend_name(std::string_view name);

/// What a scene asks of the acceleration structures, for `auto`'s choice between CPU backends:
/// only static geometry; rigid dynamic objects (hierarchical or free instances); deforming meshes.
enum class SceneKind : std::uint8_t { static_only, rigid_dynamic, deforming };
[[nodiscard]] const char* scene_kind_name(SceneKind kind);
/// The kind of the registry's scene, from its Mesh entities' Kinematics (inferred where absent)
/// and vertex animations.
[[nodiscard]] SceneKind scene_kind(ecs::Registry& registry);

/// The backend a request names: `auto` → the first available one of backends(), with the CPU
/// backends in the order measured fastest for the scene's kind (cpu_preference); any other name
/// → itself if available. Throws specula::Error for a name no build knows, UnavailableError for
/// a backend missing from this build or machine (or none at all for `auto`), saying why.
[[nodiscard]] std::string resolve_backend(std::string_view requested,
                                          SceneKind kind = SceneKind::static_only);

/// The CPU backends in the order `auto` tries them for a kind of scene: the faster first, as
/// measured by specula_bench (docs/PERFORMANCE.md, "Choosing between CPU backends").
[[nodiscard]] std::vector<std::string_view> cpu_preference(SceneKind kind);

/// A new tracer of the named backend (resolve_backend's rules, so `auto` works too) with the
/// given primary packet width (1, 4, 8 or 16).
[[nodiscard]] std::unique_ptr<Tracer> make_tracer(std::string_view name,
                                                  std::uint32_t packet_width = 16,
                                                  SceneKind kind = SceneKind::static_only);

} // namespace specula
