#include "specula/accel/embree/embree_tracer.h"

#include "specula/accel/bvh/bvh.h"
#include "specula/accel/common/traceable_instance.h"
#include "specula/core/assert.h"
#include "specula/core/error.h"
#include "specula/render/scene_layer.h"

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <limits>

namespace specula {

namespace {
using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

/// A committed scene's bounds, as Embree computes them for the instances over it.
Aabb scene_bounds(RTCScene scene) {
  RTCBounds b;
  rtcGetSceneBounds(scene, &b);
  Aabb box;
  box.min = vec3(b.lower_x, b.lower_y, b.lower_z);
  box.max = vec3(b.upper_x, b.upper_y, b.upper_z);
  return box;
}
} // namespace

static_assert(sizeof(vec3) == 3 * sizeof(float) && sizeof(uvec3) == 3 * sizeof(std::uint32_t),
              "Embree buffers are filled with memcpy from GLM vectors");

void EmbreeTracer::on_error(void* user, RTCError code, const char* message) {
  // Embree may call this from its own build threads: keep the text under a lock for check().
  auto* self = static_cast<EmbreeTracer*>(user);
  const std::lock_guard lock(self->error_mutex_);
  self->last_error_ = "Embree error " + std::to_string(int(code)) + ": " + (message ? message : "");
}

/// A deforming mesh's stand-in tree: Specula's binned-SAH BVH over the mesh's object-space
/// triangles, refitted as Embree's BLAS is, whose SAH cost against its cost when built says how far
/// the BLAS's (unseen) topology has degraded. It is built and refitted straight from the layer's
/// tables (mesh_view) and never traced, so it keeps no copy of the geometry: the view it holds is
/// only read during build() and refit().
struct EmbreeTracer::DegradationProbe {
  accel::Bvh bvh;
  float built_cost = 0.0f;
};

namespace {

/// Mesh `mesh`'s object-space triangles in the layer's tables (indices are mesh-local).
accel::TriangleView mesh_view(const SceneTables& tables, std::uint32_t mesh) {
  const gpu::GpuMesh& m = tables.meshes[mesh];
  return {tables.positions.data() + m.first_vertex, tables.triangles.data() + m.first_triangle,
          m.triangle_count};
}

} // namespace

EmbreeTracer::EmbreeTracer(std::uint32_t packet_width, float restructure_threshold)
    : packet_width_(packet_width), restructure_threshold_(restructure_threshold) {
  set_packet_width(packet_width);
  // SPECULA_EMBREE_CONFIG adds to Embree's device configuration, e.g. "isa=avx2" to run the
  // kernels another CPU would pick (the golden tests' tolerance is about that).
  std::string config = "verbose=0";
  if (const char* extra = std::getenv("SPECULA_EMBREE_CONFIG"); extra != nullptr && *extra != '\0')
    config += std::string(",") + extra;
  device_ = rtcNewDevice(config.c_str());
  if (device_ == nullptr) throw Error("embree", "cannot create an Embree device");
  rtcSetDeviceErrorFunction(device_, &EmbreeTracer::on_error, this);
  top_ = rtcNewScene(device_);
  rtcSetSceneFlags(top_, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(top_, RTC_BUILD_QUALITY_LOW);
  rtcCommitScene(top_);
  check("creating the top-level scene");
}

EmbreeTracer::~EmbreeTracer() {
  for (auto& [slot, d] : dynamic_) {
    if (d.instance) rtcReleaseGeometry(d.instance);
    if (d.own_blas) rtcReleaseScene(d.own_blas);
  }
  for (auto& [mesh, blas] : blas_) rtcReleaseScene(blas);
  if (static_instance_) rtcReleaseGeometry(static_instance_);
  if (static_scene_) rtcReleaseScene(static_scene_);
  if (top_) rtcReleaseScene(top_);
  if (device_) rtcReleaseDevice(device_);
}

void EmbreeTracer::set_packet_width(std::uint32_t width) {
  SPECULA_ASSERT(width == 1 || width == 4 || width == 8 || width == 16);
  packet_width_ = width;
}

void EmbreeTracer::check(const char* what) {
  const RTCError code = rtcGetDeviceError(device_);
  if (code == RTC_ERROR_NONE) return;
  std::string message;
  {
    const std::lock_guard lock(error_mutex_);
    message.swap(last_error_);
  }
  if (message.empty()) message = "Embree error " + std::to_string(int(code));
  throw Error("embree", std::string(what) + ": " + message);
}

RTCGeometry EmbreeTracer::make_triangles(const SceneTables& tables, std::uint32_t mesh,
                                         RTCBuildQuality quality) {
  const gpu::GpuMesh& m = tables.meshes[mesh];
  RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), m.vertex_count));
  auto* indices = static_cast<std::uint32_t*>(
      rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                              3 * sizeof(std::uint32_t), m.triangle_count));
  if (vertices == nullptr || indices == nullptr) {
    rtcReleaseGeometry(geom);
    check("allocating a mesh");
    throw Error("embree",
                "cannot allocate a mesh of " + std::to_string(m.triangle_count) + " triangles");
  }
  std::memcpy(vertices, tables.positions.data() + m.first_vertex, m.vertex_count * sizeof(vec3));
  std::memcpy(indices, tables.triangles.data() + m.first_triangle,
              m.triangle_count * sizeof(uvec3));
  rtcSetGeometryBuildQuality(geom, quality);
  rtcCommitGeometry(geom);
  return geom;
}

void EmbreeTracer::build_deforming(const SceneTables& tables, std::uint32_t slot, Dynamic& d) {
  const std::uint32_t mesh = tables.instances[slot].mesh;
  d.own_blas = rtcNewScene(device_);
  rtcSetSceneFlags(d.own_blas, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
  d.own_mesh = make_triangles(tables, mesh, RTC_BUILD_QUALITY_REFIT);
  rtcAttachGeometry(d.own_blas, d.own_mesh);
  rtcReleaseGeometry(d.own_mesh); // the scene keeps it
  rtcCommitScene(d.own_blas);
  check("building a deforming mesh's structure");
  auto probe = std::make_shared<DegradationProbe>();
  probe->bvh.build(mesh_view(tables, mesh));
  probe->built_cost = probe->bvh.sah_cost();
  d.probe = std::move(probe);
}

void EmbreeTracer::rebuild_static(const SceneTables& tables) {
  if (static_instance_ != nullptr) {
    rtcDetachGeometry(top_, 0);
    rtcReleaseGeometry(static_instance_);
    static_instance_ = nullptr;
  }
  if (static_scene_ != nullptr) rtcReleaseScene(static_scene_);
  static_scene_ = nullptr;
  static_slot_of_geom_.clear();
  static_triangles_ = 0;
  if (tables.static_instances.empty()) return;

  static_scene_ = rtcNewScene(device_);
  rtcSetSceneFlags(static_scene_, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(static_scene_, RTC_BUILD_QUALITY_HIGH);
  // One geometry per static instance, in the layer's order: geometry id g is static_instances[g].
  for (const std::uint32_t slot : tables.static_instances) {
    RTCGeometry geom = make_triangles(tables, tables.instances[slot].mesh, RTC_BUILD_QUALITY_HIGH);
    rtcAttachGeometry(static_scene_, geom);
    rtcReleaseGeometry(geom);
    static_slot_of_geom_.push_back(slot);
  }
  static_triangles_ = tables.static_triangle_count;
  rtcCommitScene(static_scene_);
  check("building the static scene");
  static_instance_ = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(static_instance_, static_scene_);
  const mat4 identity(1.0f);
  rtcSetGeometryTransform(static_instance_, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &identity[0][0]);
  rtcCommitGeometry(static_instance_);
  rtcAttachGeometryByID(top_, static_instance_, 0);
  ++last_.static_builds;
  last_.triangles_rebuilt += static_triangles_;
}

RTCScene EmbreeTracer::shared_blas(const SceneTables& tables, std::uint32_t mesh) {
  // Built when the first instance needs it (a mesh only deforming instances use needs none).
  RTCScene& blas = blas_[mesh];
  if (blas == nullptr) {
    blas = rtcNewScene(device_);
    rtcSetSceneFlags(blas, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(blas, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = make_triangles(tables, mesh, RTC_BUILD_QUALITY_HIGH);
    rtcAttachGeometry(blas, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(blas);
    check("building a mesh's structure");
    ++last_.blas_builds;
    last_.triangles_rebuilt += tables.meshes[mesh].triangle_count;
  }
  return blas;
}

void EmbreeTracer::place(std::uint32_t slot, Dynamic& d, const mat4& world_from_object) {
  // A degenerate instance never reaches Embree's builder (accel/common/traceable_instance.h): it
  // leaves the top level, and its transform is not handed to Embree, which would invert it.
  const bool traceable = accel::traceable_instance(world_from_object, scene_bounds(d.blas));
  if (traceable) {
    rtcSetGeometryTransform(d.instance, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR,
                            &world_from_object[0][0]);
    rtcCommitGeometry(d.instance);
    if (!d.attached) rtcAttachGeometryByID(top_, d.instance, slot + 1);
  } else if (d.attached) {
    rtcDetachGeometry(top_, slot + 1);
  }
  d.attached = traceable;
}

void EmbreeTracer::release_dynamic(std::uint32_t slot) {
  const auto it = dynamic_.find(slot);
  if (it == dynamic_.end()) return;
  if (it->second.attached) rtcDetachGeometry(top_, slot + 1);
  rtcReleaseGeometry(it->second.instance);
  if (it->second.own_blas != nullptr) rtcReleaseScene(it->second.own_blas); // owns own_mesh
  dynamic_.erase(it);
}

const TracerUpdateStats& EmbreeTracer::update(const SceneLayer& layer) {
  last_ = TracerUpdateStats{};
  const SceneTables& tables = layer.tables();
  const SceneDelta& delta = layer.delta_since(synced_);
  synced_ = layer.syncs();
  bool top_dirty = false;
  if (delta.full) { // made after the layer's first sync, or syncs were skipped: start over
    std::vector<std::uint32_t> slots;
    for (const auto& [slot, d] : dynamic_) slots.push_back(slot);
    for (const std::uint32_t slot : slots) release_dynamic(slot);
    for (const auto& [mesh, blas] : blas_) rtcReleaseScene(blas);
    blas_.clear();
    top_dirty = true;
  }

  if (delta.static_rebuilt) {
    const auto start = Clock::now();
    rebuild_static(tables);
    last_.static_build_ms += ms_since(start);
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_removed) {
    release_dynamic(slot);
    ++last_.instances_removed;
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_added) {
    const auto start = Clock::now();
    const gpu::GpuInstance& inst = tables.instances[slot];
    Dynamic d;
    RTCScene blas = nullptr;
    if ((inst.flags & gpu::kInstanceDeforming) != 0) {
      build_deforming(tables, slot, d);
      ++last_.blas_builds;
      last_.triangles_rebuilt += tables.meshes[inst.mesh].triangle_count;
      blas = d.own_blas;
    } else {
      blas = shared_blas(tables, inst.mesh);
    }
    d.blas = blas;
    d.triangles = tables.meshes[inst.mesh].triangle_count;
    d.instance = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(d.instance, blas);
    place(slot, d, inst.world_from_object);
    check("adding an instance");
    dynamic_[slot] = d;
    last_.blas_build_ms += ms_since(start);
    ++last_.instances_added;
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_moved) {
    place(slot, dynamic_.at(slot), tables.instances[slot].world_from_object);
    ++last_.instances_moved;
    top_dirty = true;
  }
  for (const std::uint32_t slot : delta.instances_deformed) {
    const auto start = Clock::now();
    Dynamic& d = dynamic_.at(slot);
    const gpu::GpuMesh& m = tables.meshes[tables.instances[slot].mesh];
    auto* vertices =
        static_cast<float*>(rtcGetGeometryBufferData(d.own_mesh, RTC_BUFFER_TYPE_VERTEX, 0));
    std::memcpy(vertices, tables.positions.data() + m.first_vertex, m.vertex_count * sizeof(vec3));
    // The probe follows the vertices; past the threshold the BLAS is rebuilt instead of refitted.
    DegradationProbe& probe = *d.probe;
    probe.bvh.refit(mesh_view(tables, tables.instances[slot].mesh));
    const float cost = probe.bvh.sah_cost();
    ++last_.blas_refits; // as on the native backend: refitted, then rebuilt if degraded
    last_.refit_ms += ms_since(start);
    const auto rebuild_start = Clock::now();
    if (cost > restructure_threshold_ * probe.built_cost) {
      // A fresh BLAS (Embree keeps the topology of a REFIT-quality build): the instance now
      // points at a new scene.
      rtcReleaseScene(d.own_blas);
      build_deforming(tables, slot, d);
      d.blas = d.own_blas;
      rtcSetGeometryInstancedScene(d.instance, d.blas);
      ++last_.blas_restructures;
      last_.triangles_rebuilt += m.triangle_count;
      last_.restructure_ms += ms_since(rebuild_start);
    } else {
      rtcUpdateGeometryBuffer(d.own_mesh, RTC_BUFFER_TYPE_VERTEX, 0);
      rtcCommitGeometry(d.own_mesh);
      rtcCommitScene(d.own_blas);                // refit: the topology is unchanged
      last_.triangles_refit += m.triangle_count; // Embree refits whole (RTC_BUILD_QUALITY_REFIT)
      last_.refit_ms += ms_since(rebuild_start);
    }
    // The instance caches its scene's bounds: without this commit the top level keeps the old
    // ones, and rays miss whatever moved outside them (found by tests/accel/test_differential).
    rtcCommitGeometry(d.instance);
    place(slot, d, tables.instances[slot].world_from_object); // the mesh may have collapsed
    check("refitting a deforming mesh");
    top_dirty = true; // the instance's bounds changed
  }
  for (const std::uint32_t mesh : delta.meshes_removed) {
    if (const auto it = blas_.find(mesh); it != blas_.end()) {
      rtcReleaseScene(it->second);
      blas_.erase(it);
    }
  }
  if (top_dirty) {
    const auto start = Clock::now();
    rtcCommitScene(top_);
    check("committing the top-level scene");
    last_.top_committed = true;
    last_.top_build_ms += ms_since(start);
  }
  last_.static_triangles = static_triangles_;
  last_.triangles = static_triangles_;
  for (const auto& [slot, d] : dynamic_) {
    last_.triangles += d.triangles;
    if (d.attached)
      ++last_.dynamic_instances;
    else
      ++last_.hidden_instances;
  }
  return last_;
}

namespace {

/// Rays go to Embree's stream calls (rtcIntersect1M / rtcOccluded1M) in chunks of this many.
constexpr std::size_t kStreamChunk = 256;

void to_embree(const Ray& ray, RTCRay& r) {
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
}

RTCRay& ray_of(RTCRayHit& rh) { return rh.ray; }
RTCRay& ray_of(RTCRay& r) { return r; }

/// Embree asserts (or answers garbage) on rays with NaN or infinite components: each untraceable
/// ray of a chunk becomes a finite ray with an empty interval (tnear > tfar), which Embree skips
/// as inactive.
template <typename R>
void disable_untraceable(std::span<const Ray> rays, R* chunk, std::size_t count) {
  for (std::size_t i = 0; i < count; ++i) {
    if (traceable(rays[i])) continue;
    RTCRay& r = ray_of(chunk[i]);
    r.org_x = r.org_y = r.org_z = 0.0f;
    r.dir_x = r.dir_y = 0.0f;
    r.dir_z = 1.0f;
    r.tnear = 1.0f;
    r.tfar = 0.0f;
  }
}

} // namespace

RTCScene EmbreeTracer::ray_scene() const {
  return static_scene_ != nullptr && last_.dynamic_instances == 0 ? static_scene_ : top_;
}

void EmbreeTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
  SPECULA_ASSERT(hits.size() == rays.size());
  // Without dynamic instances the static scene is the whole scene: its rays skip the top level
  // and the identity instance (a hit's instance id is then invalid, its geometry the static one).
  RTCScene scene = ray_scene();
  const bool direct = scene == static_scene_;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  alignas(64) RTCRayHit chunk[kStreamChunk];
  for (std::size_t first = 0; first < rays.size(); first += kStreamChunk) {
    const std::size_t count = std::min(kStreamChunk, rays.size() - first);
    for (std::size_t i = 0; i < count; ++i) {
      to_embree(rays[first + i], chunk[i].ray);
      chunk[i].hit.geomID = RTC_INVALID_GEOMETRY_ID;
      chunk[i].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }
    disable_untraceable(rays.subspan(first, count), chunk, count);
    rtcIntersect1M(scene, &context, chunk, unsigned(count), sizeof(RTCRayHit));
    for (std::size_t i = 0; i < count; ++i) {
      const RTCRayHit& rh = chunk[i];
      Hit& hit = hits[first + i];
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
        hit = Hit{};
        continue;
      }
      hit.t = rh.ray.tfar;
      hit.instance = direct ? static_slot_of_geom_[rh.hit.geomID]
                            : slot_of(rh.hit.geomID, rh.hit.instID[0]);
      hit.primitive = rh.hit.primID;
      hit.uv = vec2(rh.hit.u, rh.hit.v);
      hit.object_normal = vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
    }
  }
}

void EmbreeTracer::occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const {
  SPECULA_ASSERT(occluded.size() == rays.size());
  RTCScene scene = ray_scene(); // as in intersect()
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  alignas(64) RTCRay chunk[kStreamChunk];
  for (std::size_t first = 0; first < rays.size(); first += kStreamChunk) {
    const std::size_t count = std::min(kStreamChunk, rays.size() - first);
    for (std::size_t i = 0; i < count; ++i) to_embree(rays[first + i], chunk[i]);
    disable_untraceable(rays.subspan(first, count), chunk, count);
    rtcOccluded1M(scene, &context, chunk, unsigned(count), sizeof(RTCRay));
    // Embree sets tfar to -inf on occlusion (a disabled ray keeps its tfar of 0).
    for (std::size_t i = 0; i < count; ++i) occluded[first + i] = chunk[i].tfar < 0.0f ? 1 : 0;
  }
}

void EmbreeTracer::occluded_coherent(std::span<const Ray> rays,
                                     std::span<std::uint8_t> occluded) const {
  SPECULA_ASSERT(occluded.size() == rays.size());
  if (static_scene_ == nullptr || last_.dynamic_instances != 0) {
    this->occluded(rays, occluded);
    return;
  }
  // The static scene's geometry ids are the top level's through its identity instance, and
  // occlusion reports no ids: the answers are the top level's.
  constexpr std::size_t kLanes = 16;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  for (std::size_t first = 0; first < rays.size(); first += kLanes) {
    const std::size_t count = std::min(kLanes, rays.size() - first);
    alignas(64) RTCRay16 r;
    alignas(64) int valid[kLanes];
    for (std::size_t i = 0; i < kLanes; ++i) {
      // Lanes past the end and untraceable rays (NaN, Inf) are inactive and get a harmless ray.
      const bool on = i < count && traceable(rays[first + i]);
      const Ray& ray = on ? rays[first + i] : Ray{vec3(0.0f), 1.0f, vec3(0.0f, 0.0f, 1.0f), 0.0f};
      valid[i] = on ? -1 : 0;
      r.org_x[i] = ray.origin.x;
      r.org_y[i] = ray.origin.y;
      r.org_z[i] = ray.origin.z;
      r.dir_x[i] = ray.direction.x;
      r.dir_y[i] = ray.direction.y;
      r.dir_z[i] = ray.direction.z;
      r.tnear[i] = ray.tnear;
      r.tfar[i] = ray.tfar;
      r.time[i] = 0.0f;
      r.mask[i] = 0xFFFFFFFFu;
      r.id[i] = 0;
      r.flags[i] = 0;
    }
    rtcOccluded16(valid, static_scene_, &context, &r);
    // Embree sets tfar to -inf on occlusion (an inactive lane keeps its tfar of 0).
    for (std::size_t i = 0; i < count; ++i) occluded[first + i] = r.tfar[i] < 0.0f ? 1 : 0;
  }
}

template <int N, typename RayHitN, typename IntersectN>
void EmbreeTracer::intersect_camera_packets(const PacketTile& tile, PrimaryHits& hits,
                                            const vec3& origin, IntersectN intersect_n) const {
  SPECULA_ASSERT(tile.packet_w * tile.packet_h <= std::uint32_t(N));
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  std::size_t next = 0;
  tile.for_each_block(
      [&](std::uint32_t bx0, std::uint32_t by0, std::uint32_t bx1, std::uint32_t by1) {
        alignas(64) RayHitN rh;
        alignas(64) int valid[N];
        // The block's rays are consecutive in the tile's trace order: its directions are already in
        // hits.dir_*; inactive lanes repeat the first ray (finite data, masked off).
        const int lanes = int((bx1 - bx0) * (by1 - by0));
        for (int i = 0; i < N; ++i) {
          const std::size_t k = next + std::size_t(i < lanes ? i : 0);
          valid[i] = i < lanes ? -1 : 0;
          rh.ray.org_x[i] = origin.x;
          rh.ray.org_y[i] = origin.y;
          rh.ray.org_z[i] = origin.z;
          rh.ray.dir_x[i] = hits.dir_x[k];
          rh.ray.dir_y[i] = hits.dir_y[k];
          rh.ray.dir_z[i] = hits.dir_z[k];
          rh.ray.tnear[i] = 0.0f;
          rh.ray.tfar[i] = std::numeric_limits<float>::infinity();
          rh.ray.time[i] = 0.0f;
          rh.ray.mask[i] = 0xFFFFFFFFu;
          rh.ray.id[i] = unsigned(i);
          rh.ray.flags[i] = 0;
          rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        }
        intersect_n(valid, top_, &context, &rh);
        const std::size_t bytes = std::size_t(lanes) * sizeof(float);
        std::memcpy(&hits.t[next], rh.ray.tfar, bytes); // +inf on a miss
        std::memcpy(&hits.u[next], rh.hit.u, bytes);
        std::memcpy(&hits.v[next], rh.hit.v, bytes);
        std::memcpy(&hits.ng_x[next], rh.hit.Ng_x, bytes);
        std::memcpy(&hits.ng_y[next], rh.hit.Ng_y, bytes);
        std::memcpy(&hits.ng_z[next], rh.hit.Ng_z, bytes);
        for (int i = 0; i < lanes; ++i) {
          const bool miss = rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID;
          hits.instance[next + std::size_t(i)] =
              miss ? kNoInstance : slot_of(rh.hit.geomID[i], rh.hit.instID[0][i]);
          hits.primitive[next + std::size_t(i)] = miss ? 0u : rh.hit.primID[i];
        }
        next += std::size_t(lanes);
      });
}

void EmbreeTracer::intersect_camera(const CameraRays& camera, const PacketTile& tile,
                                    PrimaryHits& hits) const {
  hits.resize(tile.pixel_count());
  camera.tile_directions(tile, hits.dir_x.data(), hits.dir_y.data(), hits.dir_z.data());
  switch (packet_width_) {
  case 16:
    intersect_camera_packets<16, RTCRayHit16>(tile, hits, camera.origin, rtcIntersect16);
    return;
  case 8:
    intersect_camera_packets<8, RTCRayHit8>(tile, hits, camera.origin, rtcIntersect8);
    return;
  case 4:
    intersect_camera_packets<4, RTCRayHit4>(tile, hits, camera.origin, rtcIntersect4);
    return;
  default: {
    // Single rays: the tile's camera rays through the batch path, 64 at a time.
    constexpr std::size_t kChunk = 64;
    Ray rays[kChunk];
    Hit out[kChunk];
    for (std::size_t first = 0; first < hits.size(); first += kChunk) {
      const std::size_t count = std::min(kChunk, hits.size() - first);
      for (std::size_t i = 0; i < count; ++i)
        rays[i] = Ray{camera.origin, 0.0f, hits.direction(first + i), std::numeric_limits<float>::infinity()};
      intersect(std::span<const Ray>(rays, count), std::span<Hit>(out, count));
      for (std::size_t i = 0; i < count; ++i) hits.set(first + i, out[i]);
    }
  }
  }
}

} // namespace specula
