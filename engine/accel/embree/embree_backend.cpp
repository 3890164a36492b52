#include "specula/accel/embree/embree_backend.h"

#include "specula/core/assert.h"
#include "specula/trace/renderer_impl.h"

namespace specula {

EmbreeBackend::EmbreeBackend(const EmbreeAccel& accel, std::uint32_t packet_width)
    : accel_(&accel), packet_width_(packet_width) {
  SPECULA_ASSERT(packet_width == 1 || packet_width == 4 || packet_width == 8 || packet_width == 16);
}

void EmbreeBackend::intersect(const Ray& ray, Hit& hit) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = ray.origin.x;
  rh.ray.org_y = ray.origin.y;
  rh.ray.org_z = ray.origin.z;
  rh.ray.tnear = ray.tnear;
  rh.ray.dir_x = ray.direction.x;
  rh.ray.dir_y = ray.direction.y;
  rh.ray.dir_z = ray.direction.z;
  rh.ray.time = 0.0f;
  rh.ray.tfar = ray.tfar;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(accel_->scene(), &context, &rh);
  accel_->resolve(rh.hit.geomID, rh.hit.instID[0], rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z, rh.hit.u,
                  rh.hit.v, rh.ray.tfar, rh.hit.primID, hit);
}

bool EmbreeBackend::occluded(const Ray& ray) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay r;
  r.org_x = ray.origin.x;
  r.org_y = ray.origin.y;
  r.org_z = ray.origin.z;
  r.tnear = ray.tnear;
  r.dir_x = ray.direction.x;
  r.dir_y = ray.direction.y;
  r.dir_z = ray.direction.z;
  r.time = 0.0f;
  r.tfar = ray.tfar;
  r.mask = 0xFFFFFFFFu;
  r.id = 0;
  r.flags = 0;
  rtcOccluded1(accel_->scene(), &context, &r);
  return r.tfar < 0.0f; // Embree sets tfar to -inf on occlusion
}

template <int N, typename RayHitN, typename IntersectN>
void EmbreeBackend::intersect_camera_packets(const CameraRays& camera, const PacketTile& tile,
                                             std::span<Hit> hits, IntersectN intersect_n) const {
  SPECULA_ASSERT(tile.packet_w * tile.packet_h <= std::uint32_t(N));
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  std::size_t next = 0;
  tile.for_each_block([&](std::uint32_t bx0, std::uint32_t by0, std::uint32_t bx1, std::uint32_t by1) {
    alignas(64) RayHitN rh;
    alignas(64) int valid[N];
    int lanes = 0;
    for (std::uint32_t y = by0; y < by1; ++y)
      for (std::uint32_t x = bx0; x < bx1; ++x, ++lanes) {
        const Ray r = camera.ray(x, y);
        rh.ray.org_x[lanes] = r.origin.x;
        rh.ray.org_y[lanes] = r.origin.y;
        rh.ray.org_z[lanes] = r.origin.z;
        rh.ray.dir_x[lanes] = r.direction.x;
        rh.ray.dir_y[lanes] = r.direction.y;
        rh.ray.dir_z[lanes] = r.direction.z;
        rh.ray.tnear[lanes] = r.tnear;
        rh.ray.tfar[lanes] = r.tfar;
      }
    for (int i = 0; i < N; ++i) {
      valid[i] = i < lanes ? -1 : 0;
      if (i >= lanes) { // inactive lanes still hold finite data
        rh.ray.org_x[i] = rh.ray.org_x[0];
        rh.ray.org_y[i] = rh.ray.org_y[0];
        rh.ray.org_z[i] = rh.ray.org_z[0];
        rh.ray.dir_x[i] = rh.ray.dir_x[0];
        rh.ray.dir_y[i] = rh.ray.dir_y[0];
        rh.ray.dir_z[i] = rh.ray.dir_z[0];
        rh.ray.tnear[i] = rh.ray.tnear[0];
        rh.ray.tfar[i] = rh.ray.tfar[0];
      }
      rh.ray.time[i] = 0.0f;
      rh.ray.mask[i] = 0xFFFFFFFFu;
      rh.ray.id[i] = unsigned(i);
      rh.ray.flags[i] = 0;
      rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    intersect_n(valid, accel_->scene(), &context, &rh);
    for (int i = 0; i < lanes; ++i)
      accel_->resolve(rh.hit.geomID[i], rh.hit.instID[0][i], rh.hit.Ng_x[i], rh.hit.Ng_y[i],
                      rh.hit.Ng_z[i], rh.hit.u[i], rh.hit.v[i], rh.ray.tfar[i], rh.hit.primID[i],
                      hits[next + std::size_t(i)]);
    next += std::size_t(lanes);
  });
}

void EmbreeBackend::intersect_camera(const CameraRays& camera, const PacketTile& tile,
                                     std::span<Hit> hits) const {
  switch (packet_width_) {
  case 16: intersect_camera_packets<16, RTCRayHit16>(camera, tile, hits, rtcIntersect16); return;
  case 8: intersect_camera_packets<8, RTCRayHit8>(camera, tile, hits, rtcIntersect8); return;
  case 4: intersect_camera_packets<4, RTCRayHit4>(camera, tile, hits, rtcIntersect4); return;
  default: {
    std::size_t i = 0;
    tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) { intersect(camera.ray(x, y), hits[i++]); });
  }
  }
}

template FrameStats render_frame<EmbreeBackend>(const EmbreeBackend&, const Camera&,
                                                std::span<const SceneLight>, const TraceSettings&,
                                                Framebuffer&);
template std::uint64_t trace_primary_frame<EmbreeBackend>(const EmbreeBackend&, const Camera&,
                                                          std::uint32_t, std::uint32_t,
                                                          const TraceSettings&);

} // namespace specula
