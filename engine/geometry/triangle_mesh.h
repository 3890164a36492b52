#pragma once
/// \file
/// Shared triangle geometry: what a Mesh component points at. Flat arrays, 32-bit indices.

#include "specula/core/math.h"

#include <cstdint>
#include <string>
#include <vector>

namespace specula {

struct TriangleMesh {
  std::vector<vec3> positions;
  /// Per-vertex normals; empty means "use face normals" (compute_vertex_normals fills them).
  std::vector<vec3> normals;
  /// Optional per-vertex texture coordinates (empty or one per position).
  std::vector<vec2> uvs;
  /// Three vertex indices per triangle.
  std::vector<uvec3> triangles;

  [[nodiscard]] std::size_t vertex_count() const { return positions.size(); }
  [[nodiscard]] std::size_t triangle_count() const { return triangles.size(); }
  [[nodiscard]] Aabb bounds() const;

  /// Throws specula::Error(source, ...) naming the first problem: non-finite positions, normals
  /// or uvs, a position coordinate outside ±kMaxCoordinate (core/math.h), array sizes that
  /// disagree, indices out of range, no triangles.
  void validate(const std::string& source) const;

  /// Area-weighted smooth normals from the triangles (replaces `normals`). Vertices that only
  /// touch degenerate triangles get +Z.
  void compute_vertex_normals();
};

} // namespace specula
