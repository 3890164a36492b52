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

void DeviceCache::upload(const cache::RayCacheStore& store, std::uint32_t slots, bool lookups) {
  const VkDeviceSize range = context_.info().max_storage_buffer_range;
  std::vector<GpuCube> table(std::max(1u, slots));
  for (GpuCube& c : table) c = GpuCube{vec3(0.0f), 0, 0, kCubeNone, 1.0f, 0, 0, 0, 0, 1.0f};
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < store.cube_count(); ++i) total += store.cube(i).texels.size();
  if (total * sizeof(cache::Texel) > range)
    throw Error("vulkan", "ray-cache cubes need " + std::to_string(total * 16) +
                              " bytes of texels, more than a storage buffer holds (" +
                              std::to_string(range) + ")");
  if (ensure_size(context_, texels_, total * sizeof(cache::Texel)))
    uploaded_.clear(); // a new buffer: every cube goes up
  std::vector<Uploaded> now;
  texels_uploaded_ = 0;
  std::uint32_t first = 0;
  for (std::size_t i = 0; i < store.cube_count(); ++i) {
    const cache::CubeView v = store.cube(i);
    if (v.instance >= table.size()) throw Error("vulkan", "ray-cache cube of an unknown instance");
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
    c.flags = lookups && v.enabled ? kCubeEnabled : 0u;
    c.verify_every = v.verify_every;
    c.index = std::uint32_t(i);
    c.frame = store.verify_frame();
    c.cos_half_texel = cache::march_cos_half_texel(v.resolution);
    const Uploaded u{v.owner.index, first, v.resolution, v.generation};
    const bool same = i < uploaded_.size() && uploaded_[i].owner == u.owner &&
                      uploaded_[i].first == u.first && uploaded_[i].resolution == u.resolution &&
                      uploaded_[i].generation == u.generation;
    if (!same) {
      texels_.upload(v.texels.data(), v.texels.size_bytes(), VkDeviceSize(first) * 16);
      texels_uploaded_ += v.texels.size();
    }
    now.push_back(u);
    first += std::uint32_t(v.texels.size());
  }
  uploaded_ = std::move(now);
  const VkDeviceSize table_bytes = table.size() * sizeof(GpuCube);
  ensure_size(context_, cubes_, table_bytes, MemoryKind::host);
  cubes_.upload(table.data(), table_bytes);
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
    if ((g.packed >> 16) & 1u) {
      queries.push_back(LeavingQuery{g.instance, g.pixel, depth, g.origin, g.direction});
      queried.push_back(k);
    }
  }
  // The lookups the kernels made, made again on the store: its counters (lookups, outdated,
  // rejected) come out as the CPU integrator's, and the answers check the device's.
  std::vector<CachedRadiance> answers(queries.size());
  store.lookup(queries, answers);
  std::uint64_t differ = 0;
  for (std::size_t q = 0; q < queries.size(); ++q) {
    LeavingRadiance& r = leaving[queried[q]];
    const CacheAnswer a = answers[q].answer;
    // A verified ray's error is against the texel the kernel read: the store's (texels change
    // only at the frame's end).
    if (a == CacheAnswer::Verify) r.cached = answers[q].radiance;
    // A cached miss (UseIfClear) is used with its occlusion ray, or traced after it.
    const bool agree = a == CacheAnswer::Trace    ? r.answer == CacheAnswer::Trace
                       : a == CacheAnswer::Verify ? r.answer == CacheAnswer::Verify
                       : a == CacheAnswer::Use
                           ? r.answer == CacheAnswer::Use && r.rays == 0
                           : (r.answer == CacheAnswer::Use && r.rays == 1) ||
                                 (r.answer == CacheAnswer::Trace && r.rays >= 2);
    differ += agree ? 0u : 1u;
  }
  store.leaving(leaving);
  return differ;
}

} // namespace specula::gpu
