#include "specula/accel/grid/grid.h"

#include "specula/core/error.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>

namespace specula::accel {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

/// Akenine-Möller's separating-axis test of a triangle against the box centre ± half: the three
/// box normals, the triangle's normal and the nine cross products of box axes and triangle edges.
/// A degenerate triangle (zero normal or edges) only loses the axes that vanish, so the test stays
/// conservative.
[[nodiscard]] bool triangle_overlaps_box(const vec3& centre, const vec3& half, const vec3& p0,
                                         const vec3& p1, const vec3& p2) {
  const vec3 v0 = p0 - centre, v1 = p1 - centre, v2 = p2 - centre;
  // Box normals: the triangle's own box against the cell.
  for (int a = 0; a < 3; ++a) {
    if (std::min({v0[a], v1[a], v2[a]}) > half[a] || std::max({v0[a], v1[a], v2[a]}) < -half[a])
      return false;
  }
  const vec3 edges[3] = {v1 - v0, v2 - v1, v0 - v2};
  // Triangle normal: the plane against the box's projected radius. For a (nearly) collinear
  // triangle the computed normal is rounding noise pointing anywhere, and its "plane" would cut
  // cells the segment crosses: skip it then (the edge axes below still separate exactly).
  const vec3 n = glm::cross(edges[0], edges[1]);
  const float noise = 64.0f * std::numeric_limits<float>::epsilon() * glm::length(edges[0]) *
                      glm::length(edges[1]);
  if (glm::length(n) > noise && std::abs(glm::dot(n, v0)) > glm::dot(half, glm::abs(n)))
    return false;
  // Edge × box axis.
  for (const vec3& e : edges) {
    for (int a = 0; a < 3; ++a) {
      vec3 unit(0.0f);
      unit[a] = 1.0f;
      const vec3 axis = glm::cross(unit, e);
      const float d0 = glm::dot(axis, v0), d1 = glm::dot(axis, v1), d2 = glm::dot(axis, v2);
      const float radius = glm::dot(half, glm::abs(axis));
      if (std::min({d0, d1, d2}) > radius || std::max({d0, d1, d2}) < -radius) return false;
    }
  }
  return true;
}

struct Resolution {
  float side = 1.0f;
  uvec3 cells{1};
};

/// Cubical cells, about `target` of them over `extent`. An axis shorter than one cell (a flat or
/// thin scene) drops out of the volume and the side is recomputed from the area or length of the
/// rest, so a plane gets a square grid of ≈ target cells rather than a handful of slabs.
[[nodiscard]] Resolution choose_resolution(const vec3& extent, double target, float min_side,
                                           std::uint32_t max_cells) {
  const float longest = std::max({extent.x, extent.y, extent.z});
  bool active[3] = {extent.x > 0.0f, extent.y > 0.0f, extent.z > 0.0f};
  double side = 0.0;
  for (int pass = 0; pass < 3; ++pass) {
    int dims = 0;
    double measure = 1.0;
    for (int a = 0; a < 3; ++a) {
      if (active[a]) {
        ++dims;
        measure *= double(extent[a]);
      }
    }
    if (dims == 0) break;
    side = std::pow(measure / target, 1.0 / double(dims));
    bool dropped = false;
    for (int a = 0; a < 3; ++a) {
      if (active[a] && double(extent[a]) < side) {
        active[a] = false;
        dropped = true;
      }
    }
    if (!dropped) break;
  }
  if (!(side > 0.0) || !std::isfinite(side)) side = longest > 0.0f ? double(longest) : 1.0;
  side = std::max({side, double(min_side), double(longest) / double(kGridMaxAxisResolution)});

  Resolution out;
  for (int iteration = 0; iteration < 64; ++iteration) {
    std::uint64_t total = 1;
    for (int a = 0; a < 3; ++a) {
      const double n = std::ceil(double(extent[a]) / side);
      out.cells[a] = std::uint32_t(std::clamp(n, 1.0, double(kGridMaxAxisResolution)));
      total *= out.cells[a];
    }
    if (total <= max_cells) break;
    // Shrink the count by the missing factor (a little more, so this ends in a step or two).
    side *= std::max(1.01, std::cbrt(double(total) / double(max_cells)));
  }
  out.side = float(side);
  return out;
}

/// Finite and within ±kGridMaxCoordinate, so that the grid's own spans and products stay finite.
[[nodiscard]] bool usable(const vec3& p) {
  return is_finite(p) && glm::all(glm::lessThanEqual(glm::abs(p), vec3(kGridMaxCoordinate)));
}

template <typename F>
void for_each_range(std::size_t count, F&& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) body(i);
                    });
}

} // namespace

uvec3 UniformGrid::cell_of(const vec3& p) const {
  uvec3 c(0);
  for (int a = 0; a < 3; ++a) {
    const float q = (p[a] - header_.bounds_min[a]) * header_.inv_cell_size;
    const float hi = float(header_.resolution[a] - 1);
    c[a] = std::uint32_t(std::floor(std::clamp(q, 0.0f, hi))); // clamp first: NaN-free, no overflow
  }
  return c;
}

Aabb UniformGrid::bounds() const {
  if (empty()) return Aabb{};
  return Aabb{header_.bounds_min, header_.bounds_max};
}

void UniformGrid::build(const TriangleView& tris, const GridBuildOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  tris_ = tris;
  header_ = gpu::GridHeader{};
  cell_start_.clear();
  indices_.clear();
  stats_ = GridStats{};
  margin_ = 0.0f;

  // ---- Valid triangles and their bounds ---------------------------------------------------------
  std::vector<std::uint32_t> valid;
  valid.reserve(tris.count);
  Aabb box;
  for (std::uint32_t i = 0; i < tris.count; ++i) {
    const vec3 &p0 = tris.vertex(i, 0), &p1 = tris.vertex(i, 1), &p2 = tris.vertex(i, 2);
    if (!usable(p0) || !usable(p1) || !usable(p2)) continue;
    valid.push_back(i);
    box.grow(p0);
    box.grow(p1);
    box.grow(p2);
  }
  if (valid.empty()) {
    stats_.build_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return;
  }

  // ---- Resolution -------------------------------------------------------------------------------
  const vec3 extent = box.extent();
  const vec3 abs_max = glm::max(glm::abs(box.min), glm::abs(box.max));
  const float magnitude = std::max({abs_max.x, abs_max.y, abs_max.z});
  // A cell smaller than ~8 float steps of the coordinates cannot be told apart from its
  // neighbours; far from the origin the side never goes below that.
  const float min_side = std::max(magnitude * 0x1p-20f, std::numeric_limits<float>::min());
  const float density = std::isfinite(options.density) && options.density > 0.0f
                            ? options.density
                            : GridBuildOptions{}.density;
  const std::uint32_t max_cells = std::clamp(options.max_cells, 1u, 1u << 30);
  const double target = std::clamp(double(density) * double(valid.size()), 1.0, double(max_cells));
  const Resolution res = choose_resolution(extent, target, min_side, max_cells);

  // Centre the grid on the triangles: a flat axis gets half a cell on either side of its plane.
  gpu::GridHeader& g = header_;
  g.cell_size = res.side;
  g.inv_cell_size = 1.0f / res.side;
  g.resolution = res.cells;
  g.cell_count = res.cells.x * res.cells.y * res.cells.z;
  const vec3 span = vec3(res.cells) * res.side;
  g.bounds_min = box.min - 0.5f * glm::max(span - extent, vec3(0.0f));
  g.bounds_max = glm::max(g.bounds_min + span, box.max);
  // Rounding in the traversal's cell boundaries (a few float steps of the coordinates, a fraction
  // of a cell) must never put a hit point in a cell that does not list its triangle.
  margin_ = res.side * 1e-3f + magnitude * 0x1p-21f;

  // ---- Cells of each triangle -------------------------------------------------------------------
  const float margin = margin_;
  const vec3 half(0.5f * res.side + margin);
  const auto for_each_cell = [&](std::uint32_t prim, auto&& visit) {
    const vec3 &p0 = tris.vertex(prim, 0), &p1 = tris.vertex(prim, 1), &p2 = tris.vertex(prim, 2);
    const vec3 lo_p = glm::min(p0, glm::min(p1, p2)) - margin;
    const vec3 hi_p = glm::max(p0, glm::max(p1, p2)) + margin;
    const uvec3 lo = cell_of(lo_p), hi = cell_of(hi_p);
    if (lo == hi) {
      visit(lo.x + g.resolution.x * (lo.y + g.resolution.y * lo.z));
      return;
    }
    for (std::uint32_t z = lo.z; z <= hi.z; ++z)
      for (std::uint32_t y = lo.y; y <= hi.y; ++y)
        for (std::uint32_t x = lo.x; x <= hi.x; ++x) {
          const vec3 centre = g.bounds_min + (vec3(float(x), float(y), float(z)) + 0.5f) * res.side;
          if (triangle_overlaps_box(centre, half, p0, p1, p2))
            visit(x + g.resolution.x * (y + g.resolution.y * z));
        }
  };

  // ---- Count, prefix sum, fill ------------------------------------------------------------------
  std::vector<std::uint32_t> counts(g.cell_count, 0u);
  for_each_range(valid.size(), [&](std::size_t i) {
    for_each_cell(valid[i], [&](std::uint32_t c) {
      std::atomic_ref<std::uint32_t>(counts[c]).fetch_add(1u, std::memory_order_relaxed);
    });
  });
  cell_start_.resize(std::size_t(g.cell_count) + 1);
  std::uint64_t total = 0;
  for (std::uint32_t c = 0; c < g.cell_count; ++c) {
    cell_start_[c] = std::uint32_t(total);
    total += counts[c];
    if (total > std::numeric_limits<std::uint32_t>::max())
      throw Error("uniform grid: more than 2^32 - 1 cell entries (" + std::to_string(valid.size()) +
                  " triangles, " + std::to_string(g.cell_count) + " cells)");
  }
  cell_start_[g.cell_count] = std::uint32_t(total);
  indices_.resize(std::size_t(total));
  std::copy(cell_start_.begin(), cell_start_.end() - 1, counts.begin()); // counts become cursors
  for_each_range(valid.size(), [&](std::size_t i) {
    const std::uint32_t prim = valid[i];
    for_each_cell(prim, [&](std::uint32_t c) {
      const std::uint32_t slot =
          std::atomic_ref<std::uint32_t>(counts[c]).fetch_add(1u, std::memory_order_relaxed);
      indices_[slot] = prim;
    });
  });
  // The fill order depends on the threads; sorting each cell makes the arrays deterministic.
  for_each_range(g.cell_count, [&](std::size_t c) {
    std::sort(indices_.begin() + cell_start_[c], indices_.begin() + cell_start_[c + 1]);
  });

  // ---- Stats ------------------------------------------------------------------------------------
  std::uint32_t empty_cells = 0;
  for (std::uint32_t c = 0; c < g.cell_count; ++c)
    empty_cells += cell_start_[c] == cell_start_[c + 1];
  stats_.cells = g.cell_count;
  stats_.references = total;
  stats_.empty_cells = empty_cells;
  const std::uint32_t nonempty = g.cell_count - empty_cells;
  stats_.avg_per_nonempty = nonempty ? float(double(total) / double(nonempty)) : 0.0f;
  stats_.bytes =
      sizeof(gpu::GridHeader) + sizeof(std::uint32_t) * (cell_start_.size() + indices_.size());
  stats_.build_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

template <TriangleTest Test, bool Any>
bool UniformGrid::traverse(PreparedRay& r, TriangleHit* hit, GridTraceInfo* info) const {
  if (empty() || !r.valid()) return false;
  const gpu::GridHeader& g = header_;

  // ---- Clip to the grid, in double --------------------------------------------------------------
  // With the origin far away (1e6) a float entry distance is off by more than a small cell, and
  // the walk would start past cells the ray crosses. Once per ray, so double costs nothing here (a
  // GPU port would use intersect_box and step back a cell instead).
  double t0 = r.tnear, t1 = r.tfar;
  for (int a = 0; a < 3; ++a) {
    const double o = r.org[a], lo = g.bounds_min[a], hi = g.bounds_max[a];
    if (r.dir[a] == 0.0f) {
      if (o < lo || o > hi) return false;
      continue;
    }
    const double inv = 1.0 / double(r.dir[a]);
    double tn = (lo - o) * inv, tf = (hi - o) * inv;
    if (tn > tf) std::swap(tn, tf);
    t0 = std::max(t0, tn);
    t1 = std::min(t1, tf);
  }
  if (!(t0 <= t1)) return false;

  // ---- DDA set-up (Amanatides & Woo) in grid units from the entry point -------------------------
  // Distances s are measured from t0 and the next plane's distance is recomputed from the cell
  // index at each step rather than accumulated, so neither a far origin nor a thousand steps
  // shifts a boundary.
  int cell[3], step[3], out[3];
  float q[3], scale[3], s_next[3];
  for (int a = 0; a < 3; ++a) {
    const double p = double(r.org[a]) + t0 * double(r.dir[a]);
    const double qa = (p - double(g.bounds_min[a])) / double(g.cell_size);
    const int last = int(g.resolution[a]) - 1;
    cell[a] = int(std::clamp(std::floor(qa), 0.0, double(last)));
    q[a] = float(qa);
    scale[a] = float(double(g.cell_size) / double(r.dir[a])); // ±inf for a zero component
    if (r.dir[a] > 0.0f && std::isfinite(scale[a])) {
      step[a] = 1;
      out[a] = last + 1;
      s_next[a] = (float(cell[a] + 1) - q[a]) * scale[a];
    } else if (r.dir[a] < 0.0f && std::isfinite(scale[a])) {
      step[a] = -1;
      out[a] = -1;
      s_next[a] = (float(cell[a]) - q[a]) * scale[a];
    } else { // parallel to this axis's planes (or so nearly that a cell is infinitely far)
      step[a] = 0;
      out[a] = -2;
      s_next[a] = kInf;
    }
  }

  // ---- Walk -------------------------------------------------------------------------------------
  // A cell's triangles may be hit beyond the cell (a triangle spanning several cells), so the walk
  // stops only once the closest hit so far lies within the cells visited: s(t_hit) <= s_exit. The
  // same test ends a ray whose own tfar lies in the current cell.
  const std::uint32_t max_steps = g.resolution.x + g.resolution.y + g.resolution.z + 3;
  float s_tfar = float(double(r.tfar) - t0);
  bool found = false;
  bool bounded = true;
  std::uint32_t visited = 0, tested = 0;
  for (std::uint32_t n = 0; n < max_steps; ++n) {
    const std::uint32_t c =
        std::uint32_t(cell[0]) +
        g.resolution.x * (std::uint32_t(cell[1]) + g.resolution.y * std::uint32_t(cell[2]));
    const std::uint32_t begin = cell_start_[c], end = cell_start_[c + 1];
    ++visited;
    tested += end - begin;
    if (info != nullptr && info->cells != nullptr) info->cells->push_back(c);
    bool closer = false;
    for (std::uint32_t i = begin; i < end; ++i) {
      if constexpr (Any) {
        if (intersect_any<Test>(r, tris_, indices_[i])) {
          if (info) {
            info->cells_visited = visited;
            info->triangles_tested = tested - (end - i - 1);
            info->step_bound_hit = false;
          }
          return true;
        }
      } else {
        closer |= intersect_closest<Test>(r, tris_, indices_[i], *hit);
      }
    }
    if (closer) {
      found = true;
      s_tfar = float(double(r.tfar) - t0);
    }
    const int axis =
        s_next[0] < s_next[1] ? (s_next[0] < s_next[2] ? 0 : 2) : (s_next[1] < s_next[2] ? 1 : 2);
    if (s_tfar <= s_next[axis]) {
      bounded = false;
      break;
    }
    cell[axis] += step[axis];
    if (cell[axis] == out[axis]) {
      bounded = false;
      break;
    }
    s_next[axis] = (float(cell[axis] + (step[axis] > 0 ? 1 : 0)) - q[axis]) * scale[axis];
  }
  if (info) {
    info->cells_visited = visited;
    info->triangles_tested = tested;
    info->step_bound_hit = bounded;
  }
  return found;
}

bool UniformGrid::intersect(PreparedRay& r, TriangleHit& hit, TriangleTest test,
                            GridTraceInfo* info) const {
  return test == TriangleTest::watertight
             ? traverse<TriangleTest::watertight, false>(r, &hit, info)
             : traverse<TriangleTest::moller_trumbore, false>(r, &hit, info);
}

bool UniformGrid::occluded(const PreparedRay& r, TriangleTest test, GridTraceInfo* info) const {
  PreparedRay ray = r; // traverse() writes tfar only when it looks for the closest hit
  return test == TriangleTest::watertight
             ? traverse<TriangleTest::watertight, true>(ray, nullptr, info)
             : traverse<TriangleTest::moller_trumbore, true>(ray, nullptr, info);
}

} // namespace specula::accel
