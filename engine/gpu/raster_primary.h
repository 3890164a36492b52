#pragma once
/// \file
/// Hybrid mode's primary visibility (the ray-caching paper's fastest configuration): instead of
/// tracing the eye rays, a graphics pipeline rasterises every traced instance into a visibility
/// buffer — per pixel the instance slot and the triangle within its mesh, nearest by a reversed
/// depth buffer — with the camera of trace/camera_rays.h in render space, so a pixel centre
/// covers the triangle its primary ray meets. The vertex shader pulls the vertices from the
/// scene's pools (shaders/gbuffer.vert); frame_visibility.comp then re-intersects each pixel's ray
/// with exactly that triangle for bit-exact hits (frame_single.comp does the same at the root of
/// each walk), and the Whitted frame goes on in compute (DeviceRenderer).

#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/vk_context.h"

#include <cstdint>
#include <vector>

namespace specula {
class SceneLayer;
struct CameraRays;
} // namespace specula

namespace specula::gpu {

/// Where whole device frames get their primary hits (VulkanOptions::primary, --gpu-primary).
enum class PrimaryVisibility : std::uint8_t {
  trace,  ///< eye rays traced like every other ray
  raster, ///< hybrid mode: rasterised into a visibility buffer
};

class RasterPrimary {
public:
  /// Throws GpuError when the device cannot draw (DeviceInfo::graphics).
  RasterPrimary(Context& context, const GpuScene& scene);

  /// Gets a frame ready (GpuScene already updated): one draw per instance the tracer traces (the
  /// static set and the top level's boxes), the slot → top-level box table, images of the size.
  void prepare(const SceneLayer& layer, const CameraRays& rays, std::uint32_t width,
               std::uint32_t height);
  /// Records the raster pass and the copy of its result into visibility(); a barrier() must
  /// follow before a kernel reads it.
  void record(Commands& cmd) const;

  /// Per pixel (row major) uvec2(instance slot, triangle of its mesh); slot kNoIndex: nothing.
  [[nodiscard]] const Buffer& visibility() const { return visibility_; }
  /// Per instance slot its top-level box, kNoIndex for the static set.
  [[nodiscard]] const Buffer& slot_boxes() const { return slot_boxes_; }

  /// The near plane's distance in render-space units: geometry closer to the eye is clipped
  /// (reversed float depth keeps far geometry's precision with so small a value).
  static constexpr float kNear = 1e-4f;

private:
  struct Push {
    float origin[4], right[4], up[4], forward[4];
  };
  Context& context_;
  const GpuScene& scene_;
  Pipeline pipeline_;
  Image colour_, depth_;
  Buffer visibility_, slot_boxes_;
  std::vector<Draw> draws_;
  Push push_{};
};

} // namespace specula::gpu
