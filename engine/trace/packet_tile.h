#pragma once
/// \file
/// The order in which a tile's primary rays are traced: blocks of packet_w × packet_h pixels (one
/// coherent packet each: a compact footprint), rows inside a block, blocks row by row; blocks at
/// the tile's right and bottom edges are clipped. Backends generate rays in this order and the
/// renderer maps results back to pixels with the same walk.

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace specula {

struct PacketTile {
  std::uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0; ///< pixel rectangle [x0, x1) × [y0, y1)
  std::uint32_t packet_w = 1, packet_h = 1;

  /// The footprint for a packet width: 4×4 for 16, 4×2 for 8, 2×2 for 4, 1×1 for single rays.
  static PacketTile for_width(std::uint32_t x0, std::uint32_t y0, std::uint32_t x1,
                              std::uint32_t y1, std::uint32_t packet_width) {
    const std::uint32_t w = packet_width >= 8 ? 4 : packet_width >= 4 ? 2 : 1;
    return PacketTile{x0, y0, x1, y1, w, std::max(1u, packet_width / w)};
  }

  [[nodiscard]] std::size_t pixel_count() const { return std::size_t(x1 - x0) * (y1 - y0); }

  /// f(block_x0, block_y0, block_x1, block_y1) for every block, in trace order.
  template <typename F>
  void for_each_block(F&& f) const {
    for (std::uint32_t by = y0; by < y1; by += packet_h)
      for (std::uint32_t bx = x0; bx < x1; bx += packet_w)
        f(bx, by, std::min(bx + packet_w, x1), std::min(by + packet_h, y1));
  }

  /// f(x, y) for every pixel, in trace order.
  template <typename F>
  void for_each_pixel(F&& f) const {
    for_each_block([&](std::uint32_t bx0, std::uint32_t by0, std::uint32_t bx1, std::uint32_t by1) {
      for (std::uint32_t y = by0; y < by1; ++y)
        for (std::uint32_t x = bx0; x < bx1; ++x) f(x, y);
    });
  }
};

} // namespace specula
