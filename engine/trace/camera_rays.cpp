#include "specula/trace/camera_rays.h"

#include <vector>

namespace specula {
namespace {

/// d / |d| in place as GLM's normalize computes it: d · (1 / sqrt((x² + y²) + z²)).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) &&                             \
    !defined(__SANITIZE_ADDRESS__)
__attribute__((target_clones("avx2", "default")))
#endif
void normalize_all(std::size_t n, float* __restrict x, float* __restrict y, float* __restrict z) {
  for (std::size_t i = 0; i < n; ++i) {
    const float inv = 1.0f / std::sqrt(x[i] * x[i] + y[i] * y[i] + z[i] * z[i]);
    x[i] *= inv;
    y[i] *= inv;
    z[i] *= inv;
  }
}

} // namespace

void CameraRays::tile_directions(const PacketTile& tile, float* dx, float* dy, float* dz) const {
  // ray(): normalize((forward + sx·right) + sy·up), so the first sum depends on the column only
  // and the second term on the row only.
  const std::uint32_t w = tile.x1 - tile.x0, h = tile.y1 - tile.y0;
  vec3 columns[1024], rows[1024]; // tiles are at most 1024 pixels wide (prepare_rendering)
  std::vector<vec3> big_columns, big_rows;
  vec3* column = columns;
  vec3* row = rows;
  if (w > 1024 || h > 1024) {
    big_columns.resize(w);
    big_rows.resize(h);
    column = big_columns.data();
    row = big_rows.data();
  }
  for (std::uint32_t i = 0; i < w; ++i) {
    const float sx = 2.0f * (float(tile.x0 + i) + 0.5f) * inv_width - 1.0f;
    column[i] = forward + sx * right;
  }
  for (std::uint32_t j = 0; j < h; ++j) {
    const float sy = 1.0f - 2.0f * (float(tile.y0 + j) + 0.5f) * inv_height;
    row[j] = sy * up;
  }
  std::size_t k = 0;
  tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    const vec3 d = column[x - tile.x0] + row[y - tile.y0];
    dx[k] = d.x;
    dy[k] = d.y;
    dz[k] = d.z;
    ++k;
  });
  normalize_all(k, dx, dy, dz);
}

} // namespace specula
