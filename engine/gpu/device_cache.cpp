#include "specula/gpu/device_cache.h"

#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/render/scene_layer.h"
#include "specula/shared/cache_layout.h"

#include <algorithm>
#include <cstring>
#include <string>

namespace specula::gpu {

cache::RayCacheStore* DeviceCache::store_of(RadianceHook* hook) {
  auto* store = dynamic_cast<cache::RayCacheStore*>(hook);
  if (store == nullptr) return nullptr;
  const cache::CacheSettings& s = store->settings();
  if (s.policy != cache::CachePolicy::On && s.policy != cache::CachePolicy::Auto) return nullptr;
  return store; // every lookup mode runs in the kernels (direction, tau, march)
}

void DeviceCache::upload(cache::RayCacheStore& store, std::uint32_t slots, bool lookups) {
  const VkDeviceSize range = context_.info().max_storage_buffer_range;
  std::vector<GpuCube>& table = table_;
  table.assign(std::max(1u, slots), GpuCube{vec3(0.0f), 0, 0, kCubeNone, 1.0f, 0, 0, 0, 0, 1.0f});
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < store.cube_count(); ++i) total += store.cube(i).texels.size();
  if (total * sizeof(cache::Texel) > range)
    throw Error("vulkan", "ray-cache cubes need " + std::to_string(total * 16) +
                              " bytes of texels, more than a storage buffer holds (" +
                              std::to_string(range) + ")");
  if (ensure_size(context_, texels_, total * sizeof(cache::Texel)))
    uploaded_.clear(); // a new buffer: every cube goes up
  std::vector<Uploaded> now;
  std::vector<cache::Texel> staged;
  std::vector<VkBufferCopy> pieces;
  std::vector<std::uint32_t> changed;
  texels_uploaded_ = 0;
  every_ = records_mode_ == Records::every || store.needs_every_lookup();
  cube_of_slot_.assign(table.size(), -1);
  std::uint32_t first = 0;
  for (std::size_t i = 0; i < store.cube_count(); ++i) {
    const cache::CubeView v = store.cube(i);
    if (v.instance >= table.size()) throw Error("vulkan", "ray-cache cube of an unknown instance");
    // A lookup's answer word carries the texel it read above kAnswerTexelShift.
    if (v.texels.size() > (std::size_t(1) << (32 - kAnswerTexelShift)))
      throw Error("vulkan", "a ray-cache cube of " + std::to_string(v.resolution) +
                                "² faces has more texels than device frames address (" +
                                std::to_string(std::size_t(1) << (32 - kAnswerTexelShift)) + ")");
    GpuCube& c = table[v.instance];
    c.centre = v.centre;
    c.resolution = v.resolution;
    c.first_texel = first;
    // An off cube (auto) is neither looked up nor handed its leaving rays, as on the CPU.
    c.mode = !v.enabled                           ? kCubeNone
             : v.mode == cache::LookupMode::Tau   ? kCubeTau
             : v.mode == cache::LookupMode::March ? kCubeMarch
                                                  : kCubeDirection;
    c.cos_tau = v.cos_tau;
    c.flags = (lookups && v.enabled ? kCubeEnabled : 0u) | (every_ ? kCubeRecordAll : 0u);
    cube_of_slot_[v.instance] = std::int32_t(i);
    c.verify_every = v.verify_every;
    c.index = std::uint32_t(i);
    c.frame = store.verify_frame();
    c.cos_half_texel = cache::march_cos_half_texel(v.resolution);
    const Uploaded u{v.owner.index, first, v.resolution, v.generation};
    const bool same = i < uploaded_.size() && uploaded_[i].owner == u.owner &&
                      uploaded_[i].first == u.first && uploaded_[i].resolution == u.resolution &&
                      uploaded_[i].generation == u.generation;
    // A copy made at the generation the cube's list of changes starts from needs only those
    // texels (runs of neighbours in one piece); any other, the whole cube.
    const bool changes = !same && i < uploaded_.size() && uploaded_[i].owner == u.owner &&
                         uploaded_[i].first == u.first && uploaded_[i].resolution == u.resolution &&
                         v.changes_from != 0 && v.changes_from == uploaded_[i].generation;
    if (changes) {
      changed.assign(v.changes.begin(), v.changes.end());
      std::sort(changed.begin(), changed.end());
      changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
      for (std::size_t k = 0; k < changed.size();) {
        std::size_t end = k + 1;
        while (end < changed.size() && changed[end] == changed[end - 1] + 1) ++end;
        const VkDeviceSize bytes = (end - k) * sizeof(cache::Texel);
        pieces.push_back(VkBufferCopy{staged.size() * sizeof(cache::Texel),
                                      (VkDeviceSize(first) + changed[k]) * sizeof(cache::Texel),
                                      bytes});
        staged.insert(staged.end(), v.texels.begin() + changed[k],
                      v.texels.begin() + changed[end - 1] + 1);
        k = end;
      }
      texels_uploaded_ += changed.size();
    } else if (!same) {
      pieces.push_back(VkBufferCopy{staged.size() * sizeof(cache::Texel),
                                    VkDeviceSize(first) * sizeof(cache::Texel),
                                    v.texels.size_bytes()});
      staged.insert(staged.end(), v.texels.begin(), v.texels.end());
      texels_uploaded_ += v.texels.size();
    }
    now.push_back(u);
    first += std::uint32_t(v.texels.size());
  }
  // Every cube's texels that changed, in one copy.
  texels_.scatter(staged.data(), staged.size() * sizeof(cache::Texel), pieces);
  store.restart_journals();
  uploaded_ = std::move(now);
  const VkDeviceSize table_bytes = table.size() * sizeof(GpuCube);
  // Device-local (every lookup reads it): written by the frame's commands (record_start) where
  // vkCmdUpdateBuffer takes it, else one staging copy here.
  ensure_size(context_, cubes_, table_bytes);
  if (table_bytes > kMaxCommandUpdateBytes) cubes_.upload(table.data(), table_bytes);
  const VkDeviceSize count_bytes = table.size() * kCubeCountWords * sizeof(std::uint32_t);
  ensure_size(context_, counts_, count_bytes);
  ensure_size(context_, counts_host_, count_bytes, MemoryKind::host);
}

void DeviceCache::record_start(Commands& cmd) const {
  const VkDeviceSize table_bytes = table_.size() * sizeof(GpuCube);
  if (table_bytes <= kMaxCommandUpdateBytes) cmd.update(cubes_, table_.data(), table_bytes);
  cmd.fill(counts_, 0u);
  cmd.barrier();
}

void DeviceCache::record_counts_to_host(Commands& cmd) const {
  cmd.copy(counts_, counts_host_, table_.size() * kCubeCountWords * sizeof(std::uint32_t));
}

void DeviceCache::reserve_records(std::uint32_t capacity) {
  const VkDeviceSize range = context_.info().max_storage_buffer_range;
  record_capacity_ =
      std::uint32_t(std::min<VkDeviceSize>(capacity, range / sizeof(GpuLeavingRecord)));
  ensure_size(context_, records_, VkDeviceSize(record_capacity_) * sizeof(GpuLeavingRecord));
}

std::uint64_t DeviceCache::deliver(cache::RayCacheStore& store, const SceneTables& tables,
                                   std::uint32_t count) {
  if (count > record_capacity_)
    throw Error("vulkan", "device frame: " + std::to_string(count) +
                              " ray-cache records, room for " + std::to_string(record_capacity_));
  // The kernels' counts, by slot (kCount*: 32-bit words, and 64-bit sums low word first).
  std::vector<std::uint32_t> words(cube_of_slot_.size() * kCubeCountWords);
  std::memcpy(words.data(), counts_host_.mapped(), words.size() * sizeof(std::uint32_t));
  const auto counted = [&](std::size_t slot) {
    const std::uint32_t* w = &words[slot * kCubeCountWords];
    const auto wide = [&](std::uint32_t at) {
      return std::uint64_t(w[at]) | std::uint64_t(w[at + 1]) << 32;
    };
    cache::CubeFrameCounts n;
    n.lookups = w[kCountLookups];
    n.outdated = w[kCountOutdated];
    n.rejected = w[kCountRejected];
    n.march_steps = wide(kCountSteps);
    n.offered_rays = wide(kCountOffered);
    n.used = w[kCountUsed];
    n.used_rays = wide(kCountUsedRays);
    n.traced = w[kCountTraced];
    n.traced_rays = wide(kCountTracedRays);
    return n;
  };
  std::vector<GpuLeavingRecord> records(count);
  if (count > 0) records_.download(records.data(), records.size() * sizeof(GpuLeavingRecord));
  // The kernels append in whatever order their atomics run: sorted (by pixel, then every byte),
  // the store receives the same sequence every run (auto sums verified errors in this order).
  std::sort(records.begin(), records.end(), [](const GpuLeavingRecord& a, const GpuLeavingRecord& b) {
    if (a.pixel != b.pixel) return a.pixel < b.pixel;
    return std::memcmp(&a, &b, sizeof a) < 0;
  });
  std::vector<LeavingQuery> queries;
  std::vector<std::uint32_t> queried;
  std::vector<LeavingRadiance> leaving(count);
  std::uint64_t differ = 0;
  for (std::uint32_t k = 0; k < count; ++k) {
    const GpuLeavingRecord& g = records[k];
    const std::uint32_t depth = g.packed & 0xffu;
    const std::uint32_t answer = (g.packed >> 12) & 15u;
    LeavingRadiance& r = leaving[k];
    r.from = tables.entity(g.instance);
    r.instance = g.instance;
    r.kind = RayKind((g.packed >> 8) & 15u);
    r.exits = true;
    r.answer = answer == kAnswerUse      ? CacheAnswer::Use
               : answer == kAnswerVerify ? CacheAnswer::Verify
                                         : CacheAnswer::Trace;
    r.depth = depth;
    r.pixel = g.pixel;
    r.origin = g.origin;
    r.direction = g.direction;
    r.weight = vec3(0.0f); // read by none of the store's Whitted paths
    r.throughput = g.throughput;
    r.radiance = g.radiance;
    r.cached = vec3(0.0f);
    r.hit_t = g.hit_t;
    r.hit_entity = g.hit_entity;
    r.seen = g.seen;
    r.rays = g.rays;
    if (r.answer == CacheAnswer::Verify) {
      // Its error is against the texel the kernel read (texels change only at the frame's end).
      const std::int32_t ci = g.instance < cube_of_slot_.size() ? cube_of_slot_[g.instance] : -1;
      const cache::CubeView v = ci >= 0 ? store.cube(std::size_t(ci)) : cache::CubeView{};
      if (g.texel >= v.texels.size())
        throw Error("vulkan", "device frame: a verified ray-cache record names texel " +
                                  std::to_string(g.texel) + " of a cube of " +
                                  std::to_string(v.texels.size()));
      r.cached = cache::texel_radiance(v.texels[g.texel]);
    }
    if (every_ && ((g.packed >> 16) & 1u)) {
      queries.push_back(LeavingQuery{g.instance, g.pixel, depth, g.origin, g.direction});
      queried.push_back(k);
    }
  }
  if (every_) {
    // The lookups the kernels made, made again on the store: its counters (lookups, outdated,
    // rejected) come out as the CPU integrator's, and the answers check the device's.
    std::vector<CachedRadiance> answers(queries.size());
    store.lookup(queries, answers);
    for (std::size_t q = 0; q < queries.size(); ++q) {
      const LeavingRadiance& r = leaving[queried[q]];
      const CacheAnswer a = answers[q].answer;
      // A cached miss (UseIfClear) is used with its occlusion ray, or traced after it.
      bool agree = a == CacheAnswer::Trace    ? r.answer == CacheAnswer::Trace
                   : a == CacheAnswer::Verify ? r.answer == CacheAnswer::Verify
                   : a == CacheAnswer::Use    ? r.answer == CacheAnswer::Use && r.rays == 0
                                              : (r.answer == CacheAnswer::Use && r.rays == 1) ||
                                                 (r.answer == CacheAnswer::Trace && r.rays >= 2);
      if (a == CacheAnswer::Verify)
        agree = agree && std::memcmp(&r.cached, &answers[q].radiance, sizeof(vec3)) == 0;
      differ += agree ? 0u : 1u;
    }
    // The kernels counted every lookup as the replay did (and, recording every ray, no
    // leaving ray).
    for (std::size_t slot = 0; slot < cube_of_slot_.size(); ++slot) {
      if (cube_of_slot_[slot] < 0) continue;
      cache::CubeFrameCounts device = counted(slot);
      cache::CubeFrameCounts replay = store.frame_counts(std::size_t(cube_of_slot_[slot]));
      replay.used = replay.used_rays = replay.traced = replay.traced_rays = 0;
      differ += device == replay ? 0u : 1u;
    }
  } else {
    for (std::size_t slot = 0; slot < cube_of_slot_.size(); ++slot)
      if (cube_of_slot_[slot] >= 0)
        store.add_frame_counts(std::size_t(cube_of_slot_[slot]), counted(slot));
  }
  store.leaving(leaving);
  return differ;
}

} // namespace specula::gpu
