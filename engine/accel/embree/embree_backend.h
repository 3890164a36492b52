#pragma once
/// \file
/// The Embree tracing backend: closest-hit and occlusion queries on an EmbreeAccel, coherent
/// primary rays as rtcIntersect4/8/16 packets or single rays.

#include "specula/accel/embree/embree_accel.h"
#include "specula/geometry/ray.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/packet_tile.h"
#include "specula/trace/renderer.h"

#include <cstdint>
#include <span>

namespace specula {

class EmbreeBackend {
public:
  /// packet_width: 1, 4, 8 or 16 (anything else is a bug).
  EmbreeBackend(const EmbreeAccel& accel, std::uint32_t packet_width);

  void intersect(const Ray& ray, Hit& hit) const;
  [[nodiscard]] bool occluded(const Ray& ray) const;
  /// The tile's camera rays as one packet per block (tile.packet_w × tile.packet_h ≤ the packet
  /// width), generated straight into Embree's SoA layout; hits in the tile's trace order.
  void intersect_camera(const CameraRays& camera, const PacketTile& tile, std::span<Hit> hits) const;
  [[nodiscard]] std::uint32_t packet_width() const { return packet_width_; }
  [[nodiscard]] std::span<const Surface> surfaces() const { return accel_->surfaces(); }

private:
  template <int N, typename RayHitN, typename IntersectN>
  void intersect_camera_packets(const CameraRays& camera, const PacketTile& tile, std::span<Hit> hits,
                                IntersectN intersect_n) const;

  const EmbreeAccel* accel_;
  std::uint32_t packet_width_;
};

extern template FrameStats render_frame<EmbreeBackend>(const EmbreeBackend&, const Camera&,
                                                       std::span<const SceneLight>,
                                                       const TraceSettings&, Framebuffer&);
extern template std::uint64_t trace_primary_frame<EmbreeBackend>(const EmbreeBackend&, const Camera&,
                                                                 std::uint32_t, std::uint32_t,
                                                                 const TraceSettings&);

} // namespace specula
