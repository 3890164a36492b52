#pragma once
/// \file
/// The device's copy of a ray-cache store (cache::RayCacheStore, docs/design/ray-cache.md) for
/// the device Whitted frames (DeviceRenderer): a cube table by instance slot (resolution, centre,
/// where its texels start, mode, τ, whether it is looked up) and every cube's texels in one
/// buffer, uploaded after the CPU invalidation — only the cubes whose texels changed since the
/// last upload (CubeView::generation). The frame kernels look up rays leaving a cached object as
/// the store's lookup() does (shaders/include/frame_cache.glsl) and count each lookup per cube
/// as lookup() counts it. Of the leaving rays, they record those that may change the store — a
/// traced ray whose texel is outdated (a write), a verified one (an error sample) — and count
/// the rest (served, or traced onto a valid texel) as leaving() counts them; deliver() adds the
/// counts to the store (add_frame_counts) and hands it the records as leaving(), so the store
/// stays authoritative: its write rule, fill budget, counters and auto's decisions apply
/// unchanged. Once the cubes are filled a frame records almost nothing: no read-back, sort or
/// replay in proportion to the pixels. Records::every (and a store that needs every lookup: the
/// lookup log, fill ahead) records every leaving ray instead, and deliver() replays the lookups
/// on the store and checks them and the kernels' counts against it. --cache on in every lookup
/// mode (direction, tau, march) and --cache auto run on the device (auto's verified lookups
/// chosen by the same hash, cache::verify_chosen).

#include "specula/gpu/vk_context.h"
#include "specula/shared/cache_layout.h"

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
  /// Which leaving rays the kernels record (the rest they count).
  enum class Records {
    changes, ///< those that may change the store (the default)
    every,   ///< all of them, their lookups replayed and checked on the host
  };

  explicit DeviceCache(Context& context) : context_(context) {}

  void set_records(Records r) { records_mode_ = r; }
  [[nodiscard]] Records records_mode() const { return records_mode_; }

  /// The store behind `hook` when device frames can serve it (a RayCacheStore, policy on or
  /// auto), else nullptr.
  [[nodiscard]] static cache::RayCacheStore* store_of(RadianceHook* hook);

  /// Brings the device copy up to date with `store` for a layer of `slots` instance slots:
  /// the cubes that changed since the last upload, only their changed texels where the store
  /// kept track (CubeView::changes; its lists are restarted); `lookups`: whether the store
  /// wants lookups this frame (after begin_frame).
  void upload(cache::RayCacheStore& store, std::uint32_t slots, bool lookups);
  /// Records what the frame's first commands do for the cubes: the cube table written (in the
  /// command stream where it fits vkCmdUpdateBuffer; upload() sent a larger one) and the counts
  /// zeroed. No submit of its own.
  void record_start(Commands& cmd) const;
  /// Records the copy of the counts to host memory, for deliver(): with each submit that copies
  /// the frame's counters.
  void record_counts_to_host(Commands& cmd) const;
  /// Makes room for `capacity` records.
  void reserve_records(std::uint32_t capacity);
  /// Takes the kernels' counts (copied by the frame's last submit) and reads `count` records
  /// back (a submit only when there are any), and delivers them to the store
  /// (add_frame_counts, leaving). Where every ray was recorded, replays their lookups on the
  /// store first and returns how many recorded answers, verified texels and cubes' lookup counts
  /// differ from the replay's (0 unless the device addresses or tests a texel differently from
  /// the CPU); otherwise returns 0.
  std::uint64_t deliver(cache::RayCacheStore& store, const SceneTables& tables,
                        std::uint32_t count);

  [[nodiscard]] const Buffer& cubes() const { return cubes_; }
  [[nodiscard]] const Buffer& texels() const { return texels_; }
  [[nodiscard]] const Buffer& records() const { return records_; }
  /// kCubeCountWords words per instance slot (cache_layout.h), zeroed by the frame's commands.
  [[nodiscard]] const Buffer& counts() const { return counts_; }
  /// Whether the latest upload() asked the kernels to record every leaving ray.
  [[nodiscard]] bool records_every() const { return every_; }
  [[nodiscard]] std::uint32_t record_capacity() const { return record_capacity_; }
  /// Texels the latest upload() sent.
  [[nodiscard]] std::uint64_t texels_uploaded() const { return texels_uploaded_; }

private:
  struct Uploaded {
    std::uint32_t owner, first, resolution;
    std::uint64_t generation;
  };
  Context& context_;
  Buffer cubes_, texels_, records_, counts_;
  Buffer counts_host_;         ///< the counts as the frame's last submit left them
  std::vector<GpuCube> table_; ///< by slot, as upload() built it
  std::vector<Uploaded> uploaded_;
  std::vector<std::int32_t> cube_of_slot_; ///< the store's cube index by slot, -1: none
  Records records_mode_ = Records::changes;
  bool every_ = false;
  std::uint32_t record_capacity_ = 0;
  std::uint64_t texels_uploaded_ = 0;
};

} // namespace specula::gpu
