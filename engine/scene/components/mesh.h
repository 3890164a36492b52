#pragma once
#include "specula/core/math.h"
#include "specula/geometry/triangle_mesh.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace specula {

/// Where a mesh came from, so scenes write back losslessly (docs/scene-format.md).
struct MeshSource {
  enum class Kind { Inline, File, Primitive };
  Kind kind = Kind::Inline;
  /// Kind::File: the path as written in the scene file (relative to it) and, for glTF, the index
  /// of the mesh inside the file, whose triangle primitives are merged (load_gltf_mesh).
  /// -1 means "not stated": a .gltf/.glb file then gives its mesh 0, as the format's default
  /// (MeshLibrary), and the writer leaves "gltf_mesh" out, so the file writes back as read;
  /// other mesh formats ignore it. The glTF loader always states the index.
  std::string path;
  int gltf_mesh = -1;
  /// Kind::Primitive: "sphere", "box", "plane", "cylinder" or "cone" with its parameters (a cone
  /// with a top_radius is truncated: a frustum).
  std::string primitive;
  vec3 size{1.0f};             ///< box: edge lengths; plane: x/z lengths (y ignored)
  float radius = 1.0f;         ///< sphere, cylinder, cone
  float height = 1.0f;         ///< cylinder, cone
  float top_radius = 0.0f;     ///< cone: the radius of its top (0: pointed; below radius)
  std::uint32_t segments = 32; ///< sphere, cylinder, cone: around the axis
  std::uint32_t rings = 16;    ///< sphere: from pole to pole; plane: subdivisions per side
  friend bool operator==(const MeshSource&, const MeshSource&) = default;
};

/// Handle to shared triangle geometry (several entities may point at one TriangleMesh).
/// A deforming entity (vertex Animation) gets its own `deformed_positions`, written by
/// animation_system; `deformed_tick` says when they last changed. When its Animation also has a
/// normal track, `deformed_normals` holds the matching vertex normals; without one a deformed mesh
/// is shaded with its triangles' geometric normals (the shared geometry's would be stale).
struct Mesh {
  std::shared_ptr<const TriangleMesh> geometry;
  MeshSource source;
  std::vector<vec3> deformed_positions;
  std::uint64_t deformed_tick = 0;
  /// The animation time deformed_positions were sampled at (animation_system resamples only when
  /// the time changed, so a paused animation causes no refits).
  float deformed_time = 0.0f;
  /// Unit vertex normals sampled with deformed_positions (Animation::normals), else empty.
  std::vector<vec3> deformed_normals{};

  /// The positions to trace: the deformed ones when present, else the shared geometry's.
  [[nodiscard]] const std::vector<vec3>& positions() const {
    return deformed_positions.empty() ? geometry->positions : deformed_positions;
  }
};

} // namespace specula
