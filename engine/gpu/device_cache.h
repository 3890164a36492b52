#pragma once
/// \file
/// The device's copy of a ray-cache store (cache::RayCacheStore, docs/design/ray-cache.md) for
/// the device Whitted frames (DeviceRenderer): a cube table by instance slot (resolution, centre,
/// where its texels start, mode, τ, whether it is looked up) and every cube's texels in one
/// buffer, uploaded after the CPU invalidation — only the cubes whose texels changed since the
/// last upload (CubeView::generation). The frame kernels look up rays leaving a cached object as
/// the store's lookup() does (shaders/include/frame_cache.glsl) and record each ray they traced
/// or served for a cube; deliver() replays the lookups on the store (its counters) and hands it
/// the records as leaving(), so the store stays authoritative: its write rule, fill budget and
/// counters apply unchanged. --cache on in every lookup mode (direction, tau, march) and --cache
/// auto run on the device (auto's verified lookups chosen by the same hash,
/// cache::verify_chosen).

#include "specula/gpu/vk_context.h"

#include <cstdint>
#include <vector>

namespace specula {
class RadianceHook;
struct SceneTables;
namespace cache {
class RayCacheStore;
}
} // namespace specula

namespace specula::gpu {

class DeviceCache {
public:
  explicit DeviceCache(Context& context) : context_(context) {}

  /// The store behind `hook` when device frames can serve it (a RayCacheStore, policy on or
  /// auto), else nullptr.
  [[nodiscard]] static cache::RayCacheStore* store_of(RadianceHook* hook);

  /// Brings the device copy up to date with `store` for a layer of `slots` instance slots;
  /// `lookups`: whether the store wants lookups this frame (after begin_frame).
  void upload(const cache::RayCacheStore& store, std::uint32_t slots, bool lookups);
  /// Makes room for `capacity` records.
  void reserve_records(std::uint32_t capacity);
  /// Reads `count` records back, replays their lookups on the store and delivers them to it
  /// (leaving). Returns how many recorded answers differ from the replayed lookup's (0 unless
  /// the device addresses or tests a texel differently from the CPU).
  std::uint64_t deliver(cache::RayCacheStore& store, const SceneTables& tables,
                        std::uint32_t count);

  [[nodiscard]] const Buffer& cubes() const { return cubes_; }
  [[nodiscard]] const Buffer& texels() const { return texels_; }
  [[nodiscard]] const Buffer& records() const { return records_; }
  [[nodiscard]] std::uint32_t record_capacity() const { return record_capacity_; }
  /// Texels the latest upload() sent.
  [[nodiscard]] std::uint64_t texels_uploaded() const { return texels_uploaded_; }

private:
  struct Uploaded {
    std::uint32_t owner, first, resolution;
    std::uint64_t generation;
  };
  Context& context_;
  Buffer cubes_, texels_, records_;
  std::vector<Uploaded> uploaded_;
  std::uint32_t record_capacity_ = 0;
  std::uint64_t texels_uploaded_ = 0;
};

} // namespace specula::gpu
