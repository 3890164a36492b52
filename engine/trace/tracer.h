#pragma once
/// \file
/// What the integrators need from a tracing backend, and all they may ask of it: keep its
/// structures up to date with the scene layer, and answer batches of rays — closest hits and
/// occlusion over spans, and a tile's camera rays generated straight into its own coherent
/// packets. One virtual call per batch, never per ray, so CPU packets and streams and GPU
/// dispatches serve the same integrators. Backends are created by the tracer factory
/// (render/tracer_factory.h); integrators and systems never name a backend type.

#include "specula/geometry/ray.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/packet_tile.h"

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

namespace specula {

class SceneLayer;
class Framebuffer;
struct Camera;
struct TraceSettings;
struct FrameStats;
struct GuideBuffers;
class RadianceHook;

/// A tile's primary hits in the tile's trace order (PacketTile), one array per field (SoA), so
/// that shading runs over them as a wave. Directions are those of the camera rays traced.
struct PrimaryHits {
  std::vector<float> t, u, v;
  std::vector<float> ng_x, ng_y, ng_z; ///< geometric normal in mesh space (Hit::object_normal)
  std::vector<float> dir_x, dir_y, dir_z;
  std::vector<std::uint32_t> instance, primitive;

  void resize(std::size_t n) {
    for (auto* a : {&t, &u, &v, &ng_x, &ng_y, &ng_z, &dir_x, &dir_y, &dir_z}) a->resize(n);
    instance.resize(n);
    primitive.resize(n);
  }
  [[nodiscard]] std::size_t size() const { return t.size(); }
  [[nodiscard]] Hit hit(std::size_t i) const {
    Hit h;
    h.t = t[i];
    h.instance = instance[i];
    h.primitive = primitive[i];
    h.uv = vec2(u[i], v[i]);
    h.object_normal = vec3(ng_x[i], ng_y[i], ng_z[i]);
    return h;
  }
  [[nodiscard]] vec3 direction(std::size_t i) const { return vec3(dir_x[i], dir_y[i], dir_z[i]); }
  /// Writes entry i from a hit (the direction stays); a miss keeps Hit's own fields (t = +inf,
  /// instance = kNoInstance, primitive 0).
  void set(std::size_t i, const Hit& h) {
    t[i] = h.t;
    u[i] = h.uv.x;
    v[i] = h.uv.y;
    ng_x[i] = h.object_normal.x;
    ng_y[i] = h.object_normal.y;
    ng_z[i] = h.object_normal.z;
    instance[i] = h.instance;
    primitive[i] = h.primitive;
  }
};

/// Work done by one Tracer::update (asserted by tests, reported in the stats file).
struct TracerUpdateStats {
  std::uint32_t static_builds = 0; ///< static structure (re)built
  std::uint32_t blas_builds = 0;   ///< per-mesh structures built
  std::uint32_t blas_refits = 0;   ///< deforming meshes refitted
  std::uint32_t instances_added = 0;
  std::uint32_t instances_removed = 0;
  std::uint32_t instances_moved = 0;   ///< instance transforms rewritten
  bool top_committed = false;          ///< the top level was rebuilt or refitted
  std::uint32_t blas_restructures = 0; ///< degraded subtrees rebuilt after refits (native BVH)
  std::uint32_t static_triangles = 0;  ///< triangles in the static structure
  std::uint32_t dynamic_instances = 0; ///< instances in the top level (the static set excluded)
  /// Dynamic instances left out of the top level because their transform is singular or their
  /// world bounds degenerate (accel::traceable_instance): a scale of 0 makes an object vanish.
  std::uint32_t hidden_instances = 0;
  /// Triangles this update touched, counted per structure: built from scratch (the static
  /// structure, per-mesh structures, and the subtrees selective restructuring rebuilt) or refitted
  /// (a deforming mesh's, less its restructured part); `triangles` is every triangle the tracer
  /// holds (static and per instance), so untouched = triangles − rebuilt − refit.
  std::uint64_t triangles = 0;
  std::uint64_t triangles_rebuilt = 0;
  std::uint64_t triangles_refit = 0;
  /// Milliseconds of each step of this update (the stats file's "accel" object).
  double static_build_ms = 0.0; ///< building the static structure
  double blas_build_ms = 0.0;   ///< building per-mesh structures
  double refit_ms = 0.0;        ///< refitting deformed meshes
  double restructure_ms = 0.0;  ///< rebuilding degraded subtrees
  double top_build_ms = 0.0;    ///< the top level over the instances
  [[nodiscard]] bool no_work() const {
    return static_builds + blas_builds + blas_refits + blas_restructures + instances_added +
                   instances_removed + instances_moved ==
               0 &&
           !top_committed;
  }
};

class Tracer {
public:
  virtual ~Tracer() = default;

  /// The backend's name, as `--backend` spells it.
  [[nodiscard]] virtual std::string_view name() const = 0;

  /// Applies the layer's latest delta (SceneLayer::delta) to the backend's structures; the first
  /// call builds everything. Throws specula::Error when the backend reports a failure.
  virtual const TracerUpdateStats& update(const SceneLayer& layer) = 0;
  [[nodiscard]] virtual const TracerUpdateStats& last_update() const = 0;

  /// Closest hit of each ray within (tnear, tfar); misses get Hit::instance == kNoInstance.
  /// hits.size() == rays.size(). Safe to call from several threads at once.
  virtual void intersect(std::span<const Ray> rays, std::span<Hit> hits) const = 0;
  /// Whether anything lies within (tnear, tfar) of each ray: occluded[i] = 1 or 0.
  virtual void occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const = 0;
  /// occluded() for a coherent batch: rays of one tile in order, from nearby points towards the
  /// same lights (the shadow rays of a tile's primary hits). A backend may trace it in packets; the
  /// answers are occluded()'s (Conformance.CoherentOcclusionAnswersAsOccludedDoes, every
  /// backend). Incoherent batches (path-traced bounces) should use occluded(): packets lose there.
  virtual void occluded_coherent(std::span<const Ray> rays,
                                 std::span<std::uint8_t> occluded) const {
    this->occluded(rays, occluded);
  }
  /// The closest hits of a tile's camera rays, generated by the backend straight into its packets
  /// (no intermediate ray array), written to `hits` (resized to the tile) in the tile's trace
  /// order.
  virtual void intersect_camera(const CameraRays& camera, const PacketTile& tile,
                                PrimaryHits& hits) const = 0;

  /// Backends that render whole frames on their own device (the Vulkan path's streaming kernels)
  /// do so here for the settings they support, fill `stats` and return true; render_frame then
  /// runs no CPU integrator. Any other backend, and any settings a backend's kernels do not cover
  /// (a mode without kernels, a radiance hook, guide buffers), returns false: the CPU integrators
  /// run over this tracer's intersect/occluded.
  virtual bool render_frame_on_device(const SceneLayer& /*layer*/, const Camera& /*camera*/,
                                      const TraceSettings& /*settings*/, Framebuffer& /*out*/,
                                      RadianceHook* /*hook*/, GuideBuffers* /*guides*/,
                                      FrameStats& /*stats*/) const {
    return false;
  }

  /// Rays per coherent primary packet (1: single rays); the renderer orders primary rays to match.
  [[nodiscard]] virtual std::uint32_t packet_width() const = 0;
  /// Sets it: 1, 4, 8 or 16 (anything else is a bug).
  virtual void set_packet_width(std::uint32_t width) = 0;
};

} // namespace specula
