#include "specula/accel/native/native_tracer.h"

#include "specula/accel/common/traceable_instance.h"
#include "specula/core/assert.h"
#include "specula/core/error.h"
#include "specula/render/scene_layer.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

namespace specula {

using accel::PreparedRay;
using accel::TriangleHit;
using accel::TriangleTest;

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

const char* backend_name(StaticStructure s) {
  switch (s) {
  case StaticStructure::bvh:
    return "native-bvh";
  case StaticStructure::grid:
    return "native-grid";
  default:
    return "native";
  }
}

/// The ray in an instance's object space: same parameter t (the direction is not renormalised).
PreparedRay to_object(const PreparedRay& r, const mat4& object_from_world) {
  const vec3 org = vec3(object_from_world * vec4(r.org, 1.0f));
  const vec3 dir = mat3(object_from_world) * r.dir;
  return PreparedRay::make(org, dir, r.tnear, r.tfar);
}

} // namespace

NativeTracer::NativeTracer(std::uint32_t packet_width, NativeOptions options)
    : packet_width_(packet_width), options_(options), name_(backend_name(options.static_structure)) {
  set_packet_width(packet_width);
}

NativeTracer::~NativeTracer() = default;

void NativeTracer::set_packet_width(std::uint32_t width) {
  SPECULA_ASSERT(width == 1 || width == 4 || width == 8 || width == 16);
  packet_width_ = width;
}

// ---- Building ------------------------------------------------------------------------------------

void NativeTracer::rebuild_static(const SceneTables& tables) {
  const auto start = Clock::now();
  static_positions_.clear();
  static_triangles_.clear();
  static_first_triangle_.clear();
  static_slot_.clear();
  // The layer's static triangles index their own mesh's vertex range: make them absolute.
  for (const std::uint32_t slot : tables.static_instances) {
    const gpu::GpuMesh& m = tables.meshes[tables.instances[slot].mesh];
    const auto base = std::uint32_t(static_positions_.size());
    static_first_triangle_.push_back(std::uint32_t(static_triangles_.size()));
    static_slot_.push_back(slot);
    static_positions_.insert(static_positions_.end(), tables.positions.begin() + m.first_vertex,
                             tables.positions.begin() + m.first_vertex + m.vertex_count);
    for (std::uint32_t t = 0; t < m.triangle_count; ++t)
      static_triangles_.push_back(tables.triangles[m.first_triangle + t] + uvec3(base));
  }
  const accel::TriangleView view{static_positions_.data(), static_triangles_.data(),
                                 std::uint32_t(static_triangles_.size())};
  kd_ = accel::KdTree{};
  static_bvh_ = accel::Bvh{};
  static_wide_ = accel::WideBvh{};
  grid_ = accel::UniformGrid{};
  has_static_ = view.count > 0;
  if (has_static_) {
    switch (options_.static_structure) {
    case StaticStructure::kdtree:
      kd_.build(view);
      break;
    case StaticStructure::bvh:
      static_bvh_.build(view);
      if (options_.wide_bvh) static_wide_.build(static_bvh_, view);
      break;
    case StaticStructure::grid: {
      accel::GridBuildOptions grid_options;
      grid_options.density = options_.grid_density;
      grid_.build(view, grid_options);
      break;
    }
    }
  }
  ++last_.static_builds;
  last_.triangles_rebuilt += static_triangles_.size();
  last_.static_build_ms += ms_since(start);
}

void NativeTracer::copy_mesh(const SceneTables& tables, std::uint32_t mesh, Blas& out) {
  const gpu::GpuMesh& m = tables.meshes[mesh];
  out.positions.assign(tables.positions.begin() + m.first_vertex,
                       tables.positions.begin() + m.first_vertex + m.vertex_count);
  out.triangles.assign(tables.triangles.begin() + m.first_triangle,
                       tables.triangles.begin() + m.first_triangle + m.triangle_count);
}

const NativeTracer::Blas* NativeTracer::shared_blas(const SceneTables& tables, std::uint32_t mesh) {
  std::unique_ptr<Blas>& blas = blas_[mesh];
  if (!blas) {
    const auto start = Clock::now();
    blas = std::make_unique<Blas>();
    copy_mesh(tables, mesh, *blas);
    accel::BvhBuildOptions options;
    options.lazy = options_.lazy_blas;
    blas->bvh.build(blas->view(), options);
    if (options_.wide_bvh && !options_.lazy_blas) blas->wide.build(blas->bvh, blas->view());
    ++last_.blas_builds;
    last_.triangles_rebuilt += blas->triangles.size();
    last_.blas_build_ms += ms_since(start);
  }
  return blas.get();
}

void NativeTracer::set_transform(Dynamic& d, const mat4& world_from_object) {
  d.world_from_object = world_from_object;
  // Degenerate instances stay out of the top level (rebuild_top), and their inverse is never used.
  d.traceable = accel::traceable_instance(world_from_object, d.blas->bvh.bounds());
  d.object_from_world = d.traceable ? mat4(accel::inverse_affine(world_from_object)) : mat4(1.0f);
  d.identity = world_from_object == mat4(1.0f);
}

void NativeTracer::rebuild_top() {
  const auto start = Clock::now();
  // In slot order, so the top level does not depend on the hash map's iteration order.
  top_slot_.clear();
  // Instances of empty meshes are left out: nothing can hit them; so are degenerate ones.
  for (const auto& [slot, d] : dynamic_)
    if (!d.blas->bvh.empty() && d.traceable) top_slot_.push_back(slot);
  std::sort(top_slot_.begin(), top_slot_.end());
  std::vector<Aabb> boxes;
  boxes.reserve(top_slot_.size());
  top_entry_.clear();
  for (const std::uint32_t slot : top_slot_) {
    const Dynamic& d = dynamic_.at(slot);
    top_entry_.push_back(&d);
    boxes.push_back(d.blas->bvh.bounds().transformed(d.world_from_object));
  }
  top_ = accel::Bvh{};
  accel::BvhBuildOptions options;
  options.max_leaf = 1;
  if (!boxes.empty()) top_.build(std::span<const Aabb>(boxes), options);
  last_.top_committed = true;
  last_.top_build_ms += ms_since(start);
}

const TracerUpdateStats& NativeTracer::update(const SceneLayer& layer) {
  last_ = TracerUpdateStats{};
  const SceneTables& tables = layer.tables();
  const SceneDelta& delta = layer.delta_since(synced_);
  synced_ = layer.syncs();
  bool top_dirty = false;
  if (delta.full) { // made after the layer's first sync, or syncs were skipped: start over
    dynamic_.clear();
    blas_.clear();
    top_dirty = true;
  }

  if (delta.static_rebuilt) rebuild_static(tables);
  for (const std::uint32_t slot : delta.instances_removed) {
    dynamic_.erase(slot);
    ++last_.instances_removed;
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_added) {
    const gpu::GpuInstance& inst = tables.instances[slot];
    Dynamic d;
    if ((inst.flags & gpu::kInstanceDeforming) != 0) {
      const auto start = Clock::now();
      d.own = std::make_unique<Blas>();
      copy_mesh(tables, inst.mesh, *d.own);
      d.own->bvh.build(d.own->view());
      d.blas = d.own.get();
      ++last_.blas_builds;
      last_.triangles_rebuilt += d.own->triangles.size();
      last_.blas_build_ms += ms_since(start);
    } else {
      d.blas = shared_blas(tables, inst.mesh);
    }
    set_transform(d, inst.world_from_object);
    dynamic_[slot] = std::move(d);
    ++last_.instances_added;
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_moved) {
    set_transform(dynamic_.at(slot), tables.instances[slot].world_from_object);
    ++last_.instances_moved;
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_deformed) {
    Dynamic& d = dynamic_.at(slot);
    SPECULA_ASSERT(d.own != nullptr);
    const gpu::GpuMesh& m = tables.meshes[tables.instances[slot].mesh];
    auto start = Clock::now();
    std::copy(tables.positions.begin() + m.first_vertex,
              tables.positions.begin() + m.first_vertex + m.vertex_count, d.own->positions.begin());
    d.own->bvh.refit(d.own->view());
    ++last_.blas_refits;
    last_.refit_ms += ms_since(start);
    start = Clock::now();
    const accel::RestructureStats rs =
        d.own->bvh.restructure(d.own->view(), options_.restructure_threshold);
    last_.blas_restructures += rs.subtrees_rebuilt;
    last_.triangles_rebuilt += rs.primitives_rebuilt;
    last_.triangles_refit += d.own->triangles.size() - rs.primitives_rebuilt;
    last_.restructure_ms += ms_since(start);
    set_transform(d, d.world_from_object); // the mesh may have collapsed (or come back)
    top_dirty = true; // the instance's bounds changed
  }
  for (const std::uint32_t mesh : delta.meshes_removed) blas_.erase(mesh);
  if (top_dirty) rebuild_top();
  last_.static_triangles = std::uint32_t(static_triangles_.size());
  last_.dynamic_instances = std::uint32_t(dynamic_.size());
  last_.triangles = static_triangles_.size();
  for (const auto& [slot, d] : dynamic_) {
    last_.triangles += d.blas->triangles.size();
    if (!d.traceable) ++last_.hidden_instances;
  }
  last_.dynamic_instances -= last_.hidden_instances;
  return last_;
}

// ---- Queries -------------------------------------------------------------------------------------

void NativeTracer::resolve_static(const TriangleHit& th, Hit& hit) const {
  const auto it =
      std::upper_bound(static_first_triangle_.begin(), static_first_triangle_.end(), th.prim);
  const auto k = std::size_t(it - static_first_triangle_.begin()) - 1;
  const accel::TriangleView view{static_positions_.data(), static_triangles_.data(),
                                 std::uint32_t(static_triangles_.size())};
  hit.t = th.t;
  hit.instance = static_slot_[k];
  hit.primitive = th.prim - static_first_triangle_[k];
  hit.uv = vec2(th.u, th.v);
  hit.object_normal = accel::geometric_normal(view, th.prim);
}

template <TriangleTest Test>
void NativeTracer::intersect_dynamic(PreparedRay& r, Hit& hit) const {
  if (top_.empty()) return;
  top_.traverse(r, [&](std::uint32_t box, PreparedRay& world) {
    const Dynamic& d = *top_entry_[box];
    TriangleHit th;
    bool found;
    const auto closest = [&](PreparedRay& ray) {
      return d.blas->wide.empty() ? d.blas->bvh.intersect(ray, th, Test)
                                  : d.blas->wide.intersect(ray, th, Test);
    };
    if (d.identity) {
      found = closest(world);
    } else {
      PreparedRay local = to_object(world, d.object_from_world);
      found = closest(local);
      if (found) world.tfar = th.t;
    }
    if (found) {
      hit.t = th.t;
      hit.instance = top_slot_[box];
      hit.primitive = th.prim;
      hit.uv = vec2(th.u, th.v);
      hit.object_normal = accel::geometric_normal(d.blas->view(), th.prim);
    }
    return false;
  });
}

template <TriangleTest Test>
void NativeTracer::intersect_one(PreparedRay& r, Hit& hit) const {
  hit = Hit{};
  if (!r.valid()) return;
  if (has_static_) {
    TriangleHit th;
    bool found = false;
    switch (options_.static_structure) {
    case StaticStructure::kdtree:
      found = kd_.intersect(r, th, Test);
      break;
    case StaticStructure::bvh:
      found = options_.wide_bvh ? static_wide_.intersect(r, th, Test)
                                : static_bvh_.intersect(r, th, Test);
      break;
    case StaticStructure::grid:
      found = grid_.intersect(r, th, Test);
      break;
    }
    if (found) resolve_static(th, hit);
  }
  intersect_dynamic<Test>(r, hit);
}

template <TriangleTest Test>
bool NativeTracer::occluded_one(const PreparedRay& r) const {
  if (!r.valid()) return false;
  if (has_static_) {
    bool blocked = false;
    switch (options_.static_structure) {
    case StaticStructure::kdtree:
      blocked = kd_.occluded(r, Test);
      break;
    case StaticStructure::bvh:
      blocked = options_.wide_bvh ? static_wide_.occluded(r, Test) : static_bvh_.occluded(r, Test);
      break;
    case StaticStructure::grid:
      blocked = grid_.occluded(r, Test);
      break;
    }
    if (blocked) return true;
  }
  return occluded_dynamic<Test>(r);
}

template <TriangleTest Test>
bool NativeTracer::occluded_dynamic(const PreparedRay& r) const {
  if (top_.empty()) return false;
  bool blocked = false;
  PreparedRay world = r;
  top_.traverse(world, [&](std::uint32_t box, PreparedRay& ray) {
    const Dynamic& d = *top_entry_[box];
    const auto any = [&](const PreparedRay& q) {
      return d.blas->wide.empty() ? d.blas->bvh.occluded(q, Test) : d.blas->wide.occluded(q, Test);
    };
    blocked = d.identity ? any(ray) : any(to_object(ray, d.object_from_world));
    return blocked;
  });
  return blocked;
}

namespace {

/// The batch's ray indices grouped by the signs of their directions (in batch order within a
/// group), so that a packet holds rays that walk a tree in one order; a packet whose lanes
/// disagree on a sign walks lane by lane. Reflected rays off a curved surface change octant
/// often; grouping them made the kd-tree's reflection batches about 1.08x faster (PERFORMANCE.md
/// §6).
std::vector<std::uint32_t> octant_order(std::span<const Ray> rays) {
  auto octant = [](const Ray& r) {
    return (std::signbit(r.direction.x) ? 1u : 0u) | (std::signbit(r.direction.y) ? 2u : 0u) |
           (std::signbit(r.direction.z) ? 4u : 0u);
  };
  std::array<std::uint32_t, 9> start{};
  for (const Ray& r : rays) ++start[octant(r) + 1];
  for (std::size_t o = 1; o < start.size(); ++o) start[o] += start[o - 1];
  std::vector<std::uint32_t> order(rays.size());
  for (std::size_t i = 0; i < rays.size(); ++i) order[start[octant(rays[i])]++] = std::uint32_t(i);
  return order;
}

/// Rays order[first, first + count) of a batch as a packet (order null: the batch's own order;
/// the lanes past count inactive copies).
template <int N>
void fill_packet(std::span<const Ray> rays, const std::uint32_t* order, std::size_t first,
                 std::size_t count, accel::RayPacket<N>& p, bool* active) {
  for (std::size_t i = 0; i < std::size_t(N); ++i) {
    const std::size_t k = first + (i < count ? i : 0);
    const Ray& ray = rays[order != nullptr ? order[k] : k];
    active[i] = i < count;
    p.ox[i] = ray.origin.x;
    p.oy[i] = ray.origin.y;
    p.oz[i] = ray.origin.z;
    p.dx[i] = ray.direction.x;
    p.dy[i] = ray.direction.y;
    p.dz[i] = ray.direction.z;
    p.tnear[i] = ray.tnear;
    p.tfar[i] = ray.tfar;
  }
}

} // namespace

void NativeTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
  SPECULA_ASSERT(hits.size() == rays.size());
  // The kd-tree takes the batch as packets too, its rays grouped by octant first: its packet walk
  // gives each lane its single ray's hit to the bit (KdTree.PacketsMatchSingleRays), so a ray's
  // hit does not depend on the rays beside it in the packet. (The wide BVH's closest-hit packets
  // may keep the other of two triangles an ulp apart: its batches stay one ray at a time.)
  if (has_static_ && options_.static_structure == StaticStructure::kdtree) {
    if (accel::cpu_has_avx2())
      intersect_packets<8>(rays, hits);
    else
      intersect_packets<4>(rays, hits);
    return;
  }
  for (std::size_t i = 0; i < rays.size(); ++i) {
    PreparedRay r = PreparedRay::make(rays[i]);
    if (options_.triangle_test == TriangleTest::watertight)
      intersect_one<TriangleTest::watertight>(r, hits[i]);
    else
      intersect_one<TriangleTest::moller_trumbore>(r, hits[i]);
  }
}

void NativeTracer::occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const {
  SPECULA_ASSERT(occluded.size() == rays.size());
  // The kd-tree and the 4-wide BVH take consecutive rays as packets, as Embree's stream calls
  // take a batch of single rays: a tile's shadow rays towards one light mostly share their
  // direction signs and walk the tree together (the answers are the single rays', lane by lane).
  if (has_static_ && (options_.static_structure == StaticStructure::kdtree ||
                      (options_.static_structure == StaticStructure::bvh && options_.wide_bvh))) {
    if (accel::cpu_has_avx2())
      occluded_packets<8>(rays, occluded);
    else
      occluded_packets<4>(rays, occluded);
    return;
  }
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const PreparedRay r = PreparedRay::make(rays[i]);
    occluded[i] = options_.triangle_test == TriangleTest::watertight
                      ? occluded_one<TriangleTest::watertight>(r)
                      : occluded_one<TriangleTest::moller_trumbore>(r);
  }
}

template <int N>
void NativeTracer::intersect_packets(std::span<const Ray> rays, std::span<Hit> hits) const {
  const TriangleTest test = options_.triangle_test;
  const std::vector<std::uint32_t> order = octant_order(rays);
  for (std::size_t first = 0; first < rays.size(); first += N) {
    const std::size_t count = std::min<std::size_t>(N, rays.size() - first);
    accel::RayPacket<N> p;
    accel::PacketHits<N> ph;
    ph.clear();
    bool active[N];
    fill_packet(rays, order.data(), first, count, p, active);
    if constexpr (N == 8)
      kd_.intersect8(p, ph, active, test);
    else
      kd_.intersect4(p, ph, active, test);
    for (std::size_t i = 0; i < count; ++i) {
      const std::uint32_t index = order[first + i];
      Hit& hit = hits[index];
      hit = Hit{};
      if (ph.prim[i] != 0xFFFFFFFFu)
        resolve_static(accel::TriangleHit{ph.t[i], ph.u[i], ph.v[i], ph.prim[i]}, hit);
      if (top_.empty()) continue;
      // The dynamic instances within what the static set left of the interval, as
      // intersect_one asks them.
      const Ray& ray = rays[index];
      PreparedRay r = PreparedRay::make(ray.origin, ray.direction, ray.tnear, p.tfar[i]);
      if (!r.valid()) continue;
      if (test == TriangleTest::watertight)
        intersect_dynamic<TriangleTest::watertight>(r, hit);
      else
        intersect_dynamic<TriangleTest::moller_trumbore>(r, hit);
    }
  }
}

template <int N>
void NativeTracer::occluded_packets(std::span<const Ray> rays,
                                    std::span<std::uint8_t> occluded) const {
  const TriangleTest test = options_.triangle_test;
  const bool kd = options_.static_structure == StaticStructure::kdtree;
  // In batch order: shadow rays towards one light mostly share their signs already, and
  // grouping them by octant cost more than it saved (PERFORMANCE.md §6).
  for (std::size_t first = 0; first < rays.size(); first += N) {
    const std::size_t count = std::min<std::size_t>(N, rays.size() - first);
    accel::RayPacket<N> p;
    bool active[N];
    fill_packet(rays, nullptr, first, count, p, active);
    unsigned blocked;
    if constexpr (N == 8)
      blocked = kd ? kd_.occluded8(p, active, test) : static_wide_.occluded8(p, active, test);
    else
      blocked = kd ? kd_.occluded4(p, active, test) : static_wide_.occluded4(p, active, test);
    for (std::size_t i = 0; i < count; ++i) {
      const std::size_t index = first + i;
      bool b = ((blocked >> i) & 1u) != 0;
      if (!b && !top_.empty()) {
        const PreparedRay r = PreparedRay::make(rays[index]);
        b = r.valid() &&
            (test == TriangleTest::watertight ? occluded_dynamic<TriangleTest::watertight>(r)
                                              : occluded_dynamic<TriangleTest::moller_trumbore>(r));
      }
      occluded[index] = b ? 1 : 0;
    }
  }
}

template <int N>
void NativeTracer::intersect_camera_packets(const PacketTile& tile, PrimaryHits& hits,
                                            const vec3& origin) const {
  const bool watertight = options_.triangle_test == TriangleTest::watertight;
  std::size_t next = 0;
  tile.for_each_block([&](std::uint32_t bx0, std::uint32_t by0, std::uint32_t bx1,
                          std::uint32_t by1) {
    const auto lanes = std::size_t((bx1 - bx0) * (by1 - by0));
    // A 16-ray footprint goes through as packets of N lanes, in trace order.
    for (std::size_t first = 0; first < lanes; first += N) {
      const std::size_t count = std::min<std::size_t>(N, lanes - first);
      const std::size_t base = next + first;
      accel::RayPacket<N> rays;
      accel::PacketHits<N> ph;
      bool active[N];
      for (std::size_t i = 0; i < std::size_t(N); ++i) {
        const std::size_t k = base + (i < count ? i : 0);
        active[i] = i < count;
        rays.ox[i] = origin.x;
        rays.oy[i] = origin.y;
        rays.oz[i] = origin.z;
        rays.dx[i] = hits.dir_x[k];
        rays.dy[i] = hits.dir_y[k];
        rays.dz[i] = hits.dir_z[k];
        rays.tnear[i] = 0.0f;
        rays.tfar[i] = std::numeric_limits<float>::infinity();
      }
      ph.clear();
      if (has_static_) {
        const TriangleTest test = options_.triangle_test;
        if (options_.static_structure == StaticStructure::kdtree) {
          if constexpr (N == 8)
            kd_.intersect8(rays, ph, active, test);
          else
            kd_.intersect4(rays, ph, active, test);
        } else if (options_.static_structure == StaticStructure::bvh && options_.wide_bvh) {
          if constexpr (N == 8)
            static_wide_.intersect8(rays, ph, active, test);
          else
            static_wide_.intersect4(rays, ph, active, test);
        } else if (options_.static_structure == StaticStructure::bvh) {
          if constexpr (N == 8)
            static_bvh_.intersect8(rays, ph, active, test);
          else
            static_bvh_.intersect4(rays, ph, active, test);
        } else {
          for (std::size_t i = 0; i < count; ++i) {
            PreparedRay r = PreparedRay::make(origin, vec3(rays.dx[i], rays.dy[i], rays.dz[i]),
                                              0.0f, std::numeric_limits<float>::infinity());
            TriangleHit th;
            if (r.valid() && grid_.intersect(r, th, test)) {
              ph.t[i] = th.t;
              ph.u[i] = th.u;
              ph.v[i] = th.v;
              ph.prim[i] = th.prim;
            }
          }
        }
      }
      for (std::size_t i = 0; i < count; ++i) {
        Hit hit;
        if (ph.prim[i] != 0xFFFFFFFFu) {
          TriangleHit th;
          th.t = ph.t[i];
          th.u = ph.u[i];
          th.v = ph.v[i];
          th.prim = ph.prim[i];
          resolve_static(th, hit);
        }
        if (!top_.empty()) {
          PreparedRay r = PreparedRay::make(origin, vec3(rays.dx[i], rays.dy[i], rays.dz[i]), 0.0f,
                                            hit.t);
          if (r.valid()) {
            if (watertight)
              intersect_dynamic<TriangleTest::watertight>(r, hit);
            else
              intersect_dynamic<TriangleTest::moller_trumbore>(r, hit);
          }
        }
        hits.set(base + i, hit);
      }
    }
    next += lanes;
  });
}

void NativeTracer::intersect_camera(const CameraRays& camera, const PacketTile& tile,
                                    PrimaryHits& hits) const {
  hits.resize(tile.pixel_count());
  camera.tile_directions(tile, hits.dir_x.data(), hits.dir_y.data(), hits.dir_z.data());
  if (packet_width_ >= 8) {
    intersect_camera_packets<8>(tile, hits, camera.origin);
    return;
  }
  if (packet_width_ == 4) {
    intersect_camera_packets<4>(tile, hits, camera.origin);
    return;
  }
  const bool watertight = options_.triangle_test == TriangleTest::watertight;
  for (std::size_t k = 0; k < hits.size(); ++k) {
    PreparedRay r = PreparedRay::make(camera.origin, hits.direction(k), 0.0f,
                                      std::numeric_limits<float>::infinity());
    Hit hit;
    if (watertight)
      intersect_one<TriangleTest::watertight>(r, hit);
    else
      intersect_one<TriangleTest::moller_trumbore>(r, hit);
    hits.set(k, hit);
  }
}

} // namespace specula
