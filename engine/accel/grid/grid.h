#pragma once
/// \file
/// The uniform grid of Purcell et al., "Ray Tracing on Programmable Graphics Hardware" (SIGGRAPH
/// 2002): cubical voxels over the scene's box, each listing the triangles that overlap it, walked
/// front to back with the 3D-DDA of Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray
/// Tracing" (Eurographics 1987).
///
/// Layout (shaders/shared/accel_layout.h, uploaded as is by the Vulkan path): a gpu::GridHeader,
/// cell_start (cell count + 1 offsets) and the triangle index array; cell
/// c = x + res.x · (y + res.y · z) lists indices[cell_start[c] .. cell_start[c + 1]), ascending.
///
/// Resolution: cell count ≈ λ · triangle count, cube cells of side cbrt(volume / target), i.e.
/// res_axis = ceil(extent_axis · cbrt(λN / V)), the usual rule (as in Wald et al. 2006, "Ray
/// Tracing Animated Scenes using Coherent Grid Traversal"), at most kGridMaxAxisResolution per axis
/// and options.max_cells in all. λ = 4 by default: on a 100k-triangle surface mesh and a 100k soup
/// the ray rate is flat within noise for λ in 2–8 and falls at 16, while memory and build time grow
/// with λ. A flat scene (an axis shorter than one cell) takes the side from the area (or length)
/// of the other axes instead, and gets one cell across its flat axes, padded equally either side.
///
/// Build: two passes over the triangles (count, prefix sum, fill) into the flat arrays, each
/// triangle listed in every cell its box spans that Akenine-Möller's separating-axis test
/// ("Fast 3D Triangle-Box Overlap Testing", JGT 2001) says it overlaps. Cells are tested enlarged
/// by a small margin, so rounding in the traversal's cell boundaries never loses a triangle.

#include "specula/accel/common/ray_query.h"
#include "specula/shared/accel_layout.h"

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace specula::accel {

/// Most cells along one axis (the DDA's step bound grows with it).
inline constexpr std::uint32_t kGridMaxAxisResolution = 1024;
/// Triangles with a coordinate beyond ±2^64 are left out of the grid like non-finite ones: the
/// grid's spans stay finite, and neither triangle test survives such coordinates anyway (its
/// products of three coordinate differences overflow from about 1e13 on).
inline constexpr float kGridMaxCoordinate = 0x1p64f;

struct GridBuildOptions {
  float density = 4.0f;               ///< target cells per triangle (λ)
  std::uint32_t max_cells = 1u << 24; ///< cap on the total cell count
};

struct GridStats {
  double build_ms = 0.0;
  std::uint32_t cells = 0;
  std::uint64_t references = 0; ///< entries of the index array
  std::uint32_t empty_cells = 0;
  float avg_per_nonempty = 0.0f; ///< references per non-empty cell
  std::size_t bytes = 0;         ///< header + cell_start + indices
};

/// What one traversal did (tests and diagnostics; pass a pointer to intersect/occluded).
struct GridTraceInfo {
  std::uint32_t cells_visited = 0;
  std::uint32_t triangles_tested = 0;
  bool step_bound_hit = false; ///< the loop ran into its res.x + res.y + res.z + 3 bound
  /// When set, receives the index of every cell visited, in order (the GPU DDA's kernel test).
  std::vector<std::uint32_t>* cells = nullptr;
};

class UniformGrid {
public:
  /// Builds over `tris`, which must outlive the grid (read in place). Triangles with a NaN,
  /// infinite or beyond-kGridMaxCoordinate vertex are left out; none left gives an empty grid.
  void build(const TriangleView& tris, const GridBuildOptions& options = {});

  [[nodiscard]] bool empty() const { return header_.cell_count == 0; }
  /// The grid's box (covers every triangle listed; empty box for an empty grid).
  [[nodiscard]] Aabb bounds() const;

  /// Closest hit in (r.tnear, r.tfar). On a hit fills `hit`, sets r.tfar = hit.t, returns true.
  /// An invalid ray (!r.valid()) misses.
  bool intersect(PreparedRay& r, TriangleHit& hit, TriangleTest test = TriangleTest::watertight,
                 GridTraceInfo* info = nullptr) const;
  /// Whether any triangle lies within (r.tnear, r.tfar). An invalid ray is not occluded.
  [[nodiscard]] bool occluded(const PreparedRay& r, TriangleTest test = TriangleTest::watertight,
                              GridTraceInfo* info = nullptr) const;

  [[nodiscard]] const gpu::GridHeader& header() const { return header_; }
  [[nodiscard]] std::span<const std::uint32_t> cell_start() const { return cell_start_; }
  [[nodiscard]] std::span<const std::uint32_t> indices() const { return indices_; }
  [[nodiscard]] const GridStats& stats() const { return stats_; }
  [[nodiscard]] const TriangleView& triangles() const { return tris_; }

  /// The cell (x, y, z) holding point p, clamped into the grid (the build's own mapping).
  [[nodiscard]] uvec3 cell_of(const vec3& p) const;
  /// Slack the build adds around each cell before the overlap test (world units).
  [[nodiscard]] float cell_margin() const { return margin_; }

private:
  template <TriangleTest Test, bool Any>
  bool traverse(PreparedRay& r, TriangleHit* hit, GridTraceInfo* info) const;

  TriangleView tris_;
  gpu::GridHeader header_{};
  std::vector<std::uint32_t> cell_start_;
  std::vector<std::uint32_t> indices_;
  GridStats stats_;
  float margin_ = 0.0f;
};

} // namespace specula::accel
