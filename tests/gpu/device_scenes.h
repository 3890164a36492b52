#pragma once
// What the device-frame tests share (test_device_frames, test_device_path, test_device_cache,
// test_hybrid): whether a Vulkan device is there, a small Cornell box, and a count of the pixels
// two images differ in.
#include "../trace/scene_builder.h"
#include "specula/core/error.h"
#include "specula/gpu/vk_context.h"

#include <gtest/gtest.h>

#ifdef SPECULA_KEEP_VULKAN_DRIVER
#include <dlfcn.h>
#endif

namespace specula::test {

/// Sanitized builds only (tests/CMakeLists.txt): loads lavapipe once more and never unloads it,
/// so the blocks it keeps in its globals stay reachable when the Vulkan loader lets it go.
inline void keep_vulkan_driver_loaded() {
#ifdef SPECULA_KEEP_VULKAN_DRIVER
  static const void* const handle = ::dlopen(SPECULA_KEEP_VULKAN_DRIVER, RTLD_LAZY | RTLD_NODELETE);
  (void)handle;
#endif
}

/// Whether Context::create finds a device (lavapipe counts); `drawing`: one whose queue also draws.
inline bool have_device(bool drawing = false) {
  keep_vulkan_driver_loaded();
  try {
    const auto context = gpu::Context::create();
    return !drawing || context->info().graphics;
  } catch (const UnavailableError&) {
    return false;
  }
}

#define SPECULA_NEED_DEVICE()                                                                      \
  if (!::specula::test::have_device()) GTEST_SKIP() << "no Vulkan device on this machine"

/// A small Cornell box: coloured walls, a block, a mirror sphere and a glass sphere (smooth
/// Pixels whose values are not bit-identical in `a` and `b` (images of one size).
inline std::size_t differing_pixels(const Framebuffer& a, const Framebuffer& b) {
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i) differ += a.pixels()[i] != b.pixels()[i];
  return differ;
}

/// normals), a point light and an emitting panel (an area light); coarse spheres keep it fast on lavapipe.
inline void cornell(ecs::Registry& reg) {
  const quat flip(0.0f, 1.0f, 0.0f, 0.0f); // 180° about x: planes facing down
  Material white;
  white.base_color = vec3(0.725f, 0.71f, 0.68f);
  Material red = white, green = white, panel;
  red.base_color = vec3(0.63f, 0.065f, 0.05f);
  green.base_color = vec3(0.14f, 0.45f, 0.091f);
  panel.base_color = vec3(0.0f);
  panel.emission = vec3(4.0f, 3.4f, 2.8f);
  add_mesh(reg, primitive("plane", 1, vec3(2.0f)), at(vec3(0)), white);
  add_mesh(reg, primitive("plane", 1, vec3(2.0f)), at(vec3(0, 2, 0), vec3(1), flip), white);
  add_mesh(reg, primitive("plane", 1, vec3(2.0f)),
           at(vec3(0, 1, -1), vec3(1), quat(0.70710678f, 0.70710678f, 0, 0)), white);
  add_mesh(reg, primitive("plane", 1, vec3(2.0f)),
           at(vec3(-1, 1, 0), vec3(1), quat(0.70710678f, 0, 0, -0.70710678f)), red);
  add_mesh(reg, primitive("plane", 1, vec3(2.0f)),
           at(vec3(1, 1, 0), vec3(1), quat(0.70710678f, 0, 0, 0.70710678f)), green);
  add_mesh(reg, primitive("plane", 1, vec3(0.5f)), at(vec3(0, 1.995f, 0), vec3(1), flip), panel);
  add_mesh(reg, primitive("box", 1, vec3(0.6f, 1.2f, 0.6f)),
           at(vec3(-0.35f, 0.6f, -0.35f), vec3(1), quat(0.98901586f, 0, 0.14780942f, 0)), white);
  Material mirror;
  mirror.base_color = vec3(0.95f);
  mirror.reflectivity = 0.9f;
  add_mesh(reg, primitive("sphere", 0.3f, vec3(1), 16, 8), at(vec3(-0.45f, 0.3f, 0.45f)), mirror);
  Material glass;
  glass.base_color = vec3(1.0f);
  glass.transmission = 0.9f;
  glass.ior = 1.5f;
  add_mesh(reg, primitive("sphere", 0.3f, vec3(1), 16, 8), at(vec3(0.4f, 0.3f, 0.3f)), glass);
  test::add_point_light(reg, vec3(0, 1.85f, 0), 3.0f);
}

inline Camera cornell_camera() {
  Camera c;
  c.position = dvec3(0, 1, 3.9);
  c.look_at = dvec3(0, 1, 0);
  c.vertical_fov = glm::radians(40.0f);
  return c;
}

} // namespace specula::test
