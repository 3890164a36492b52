// Presentation (engine/present): the CPU encoding against the PNG writer, the offscreen target
// against the CPU encoding (with and without Dear ImGui over the frame), the window under a
// display (Xvfb in CI), and the input bookkeeping behind Window::poll.
#include "../gpu/device_scenes.h"
#include "specula/core/error.h"
#include "specula/image/image_io.h"
#include "specula/image/srgb.h"
#include "specula/present/input.h"
#include "specula/present/window.h"

#include <GLFW/glfw3.h>
#include <gtest/gtest.h>
#include <imgui.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <thread>

namespace specula::present {
namespace {

/// A seeded frame with values below 0, above 1 and a NaN, so clamping is exercised too.
Framebuffer random_frame(std::uint32_t width, std::uint32_t height, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> value(-0.2f, 1.4f);
  Framebuffer frame(width, height);
  for (vec3& p : frame.pixels()) p = vec3(value(rng), value(rng), value(rng));
  frame.at(0, 0).g = std::numeric_limits<float>::quiet_NaN();
  return frame;
}

std::unique_ptr<Offscreen> try_offscreen(const OffscreenSettings& settings) {
  test::keep_vulkan_driver_loaded();
  try {
    return Offscreen::create(settings);
  } catch (const UnavailableError&) {
    return nullptr;
  }
}

/// Bytes that differ, with the first one's place, for a readable failure.
::testing::AssertionResult same_image(const Rgba8Image& got, const Rgba8Image& want) {
  if (got.width != want.width || got.height != want.height)
    return ::testing::AssertionFailure() << "size " << got.width << "x" << got.height << ", want "
                                         << want.width << "x" << want.height;
  for (std::size_t i = 0; i < want.rgba.size(); ++i)
    if (got.rgba[i] != want.rgba[i]) {
      const std::size_t pixel = i / 4;
      return ::testing::AssertionFailure()
             << "pixel (" << pixel % want.width << ", " << pixel / want.width << ") channel "
             << i % 4 << ": " << int(got.rgba[i]) << ", want " << int(want.rgba[i]);
    }
  return ::testing::AssertionSuccess();
}

TEST(EncodeSrgb8, AgreesWithThePngWriter) {
  const Framebuffer frame = random_frame(29, 17, 11);
  const auto path = std::filesystem::temp_directory_path() /
                    ("specula_present_" + std::to_string(::getpid()) + ".png");
  write_png(frame, path);
  // The reader maps each 8-bit value to its exact linear value, which encodes back to itself:
  // the PNG's bytes, seen through the same encoding.
  const Framebuffer png = read_png(path);
  std::filesystem::remove(path);
  EXPECT_TRUE(same_image(encode_srgb8(frame, 29, 17), encode_srgb8(png, 29, 17)));
}

TEST(EncodeSrgb8, LetterboxesAndScalesUpBilinearly) {
  Framebuffer frame(2, 1);
  frame.at(0, 0) = vec3(1.0f, 0.0f, 0.0f);
  frame.at(1, 0) = vec3(0.0f, 0.0f, 1.0f);
  // 2:1 into 4×4: drawn 4×2 in rows 1 and 2, black bars above and below. Scaled up bilinearly in
  // linear colour: destination centres fall at source x = -0.25 (clamped to 0), 0.25, 0.75 and
  // 1.25 (clamped to 1), so red, ¾ red + ¼ blue, ¼ red + ¾ blue, blue.
  const Rgba8Image image = encode_srgb8(frame, 4, 4);
  ASSERT_EQ(image.rgba.size(), 4u * 4u * 4u);
  const float red_share[4] = {1.0f, 0.75f, 0.25f, 0.0f};
  for (std::uint32_t y = 0; y < 4; ++y)
    for (std::uint32_t x = 0; x < 4; ++x) {
      const std::uint8_t* p = &image.rgba[(y * 4 + x) * 4];
      const bool bar = y == 0 || y == 3;
      EXPECT_EQ(p[0], bar ? 0 : specula::encode_srgb8(red_share[x])) << x << "," << y;
      EXPECT_EQ(p[1], 0) << x << "," << y;
      EXPECT_EQ(p[2], bar ? 0 : specula::encode_srgb8(1.0f - red_share[x])) << x << "," << y;
      EXPECT_EQ(p[3], 255) << x << "," << y;
    }
  // Taller than wide: bars left and right.
  const Rgba8Image tall = encode_srgb8(Framebuffer(1, 2, vec3(1.0f)), 4, 4);
  for (std::uint32_t x = 0; x < 4; ++x)
    EXPECT_EQ(tall.rgba[x * 4], (x == 1 || x == 2) ? 255 : 0) << x;
}

TEST(EncodeSrgb8, ScalesDownWithNearestNeighbour) {
  // 4×1 into 2×1: each destination pixel takes the source pixel under its centre (x = 1 and 3).
  Framebuffer frame(4, 1);
  for (std::uint32_t x = 0; x < 4; ++x) frame.at(x, 0) = vec3(0.25f * float(x));
  const Rgba8Image image = encode_srgb8(frame, 2, 1);
  EXPECT_EQ(image.rgba[0], specula::encode_srgb8(0.25f));
  EXPECT_EQ(image.rgba[4], specula::encode_srgb8(0.75f));
}

TEST(Offscreen, WithoutUiReturnsTheEncodedFrame) {
  const Framebuffer frame = random_frame(37, 23, 5);
  for (const auto& [w, h] : {std::pair{37u, 23u}, std::pair{64u, 48u}, std::pair{30u, 41u}}) {
    auto target = try_offscreen({w, h, false});
    if (!target) GTEST_SKIP() << "no Vulkan device on this machine";
    EXPECT_TRUE(same_image(target->render(frame, nullptr), encode_srgb8(frame, w, h)))
        << w << "x" << h;
  }
}

TEST(Offscreen, UiWindowChangesOnlyItsRectangle) {
  constexpr std::uint32_t kW = 96, kH = 64;
  auto target = try_offscreen({kW, kH, true});
  if (!target) GTEST_SKIP() << "no Vulkan device on this machine";
  const Framebuffer frame(kW, kH, vec3(0.5f));
  const ImVec2 pos(20.0f, 10.0f), size(50.0f, 40.0f); // above style.WindowMinSize
  for (int i = 0; i < 2; ++i) { // the first frame lays the window out, the second draws it settled
    target->begin_ui();
    ImGui::SetNextWindowPos(pos);
    ImGui::SetNextWindowSize(size);
    ImGui::Begin("panel", nullptr, ImGuiWindowFlags_NoDecoration);
    ImGui::TextUnformatted("hi");
    ImGui::End();
    ImGui::Render();
  }
  const Rgba8Image image = target->render(frame, ImGui::GetDrawData());
  const Rgba8Image plain = encode_srgb8(frame, kW, kH);
  // Inside (less a pixel of anti-aliased edge) every pixel is the panel's, outside the frame's.
  int inside = 0, inside_changed = 0, outside_changed = 0;
  for (std::uint32_t y = 0; y < kH; ++y)
    for (std::uint32_t x = 0; x < kW; ++x) {
      const std::size_t i = (std::size_t(y) * kW + x) * 4;
      const bool changed = image.rgba[i] != plain.rgba[i] || image.rgba[i + 1] != plain.rgba[i + 1] ||
                           image.rgba[i + 2] != plain.rgba[i + 2];
      const bool in = x >= pos.x + 1 && x < pos.x + size.x - 1 && y >= pos.y + 1 &&
                      y < pos.y + size.y - 1;
      const bool out = x < pos.x - 1 || x >= pos.x + size.x + 1 || y < pos.y - 1 ||
                       y >= pos.y + size.y + 1;
      inside += in;
      inside_changed += in && changed;
      outside_changed += out && changed;
    }
  EXPECT_GT(inside, 0);
  EXPECT_EQ(inside_changed, inside);
  EXPECT_EQ(outside_changed, 0);
}

TEST(Offscreen, RejectsAnEmptySize) {
  EXPECT_THROW((void)Offscreen::create({0, 10, false}), std::invalid_argument);
}

// The device filter a window passes to gpu::Context: a device lacking a device extension, or
// refused by `accept`, is passed over, with a reason when none is left.
TEST(ContextOptions, PassOverDevicesThatCannotPresent) {
  if (!test::have_device()) GTEST_SKIP() << "no Vulkan device on this machine";
  gpu::Context::Options missing;
  missing.device_extensions = {"VK_SPECULA_no_such_extension"};
  EXPECT_THROW((void)gpu::Context::create(missing), UnavailableError);
  gpu::Context::Options refused;
  int asked = 0;
  refused.accept = [&](VkInstance instance, VkPhysicalDevice device, std::uint32_t) {
    asked += instance != VK_NULL_HANDLE && device != VK_NULL_HANDLE;
    return false;
  };
  try {
    (void)gpu::Context::create(refused);
    ADD_FAILURE() << "a refused device was chosen";
  } catch (const UnavailableError& e) {
    EXPECT_NE(std::string(e.what()).find("present"), std::string::npos) << e.what();
  }
  EXPECT_GT(asked, 0);
  gpu::Context::Options accepted;
  accepted.accept = [](VkInstance, VkPhysicalDevice, std::uint32_t) { return true; };
  EXPECT_NO_THROW((void)gpu::Context::create(accepted));
}

TEST(InputTracker, ReportsEdgesOncePerPoll) {
  InputTracker tracker;
  InputState input;
  tracker.key(GLFW_KEY_W, true);
  tracker.button(0, true);
  tracker.cursor(10.0, 20.0);
  tracker.finish(input);
  EXPECT_TRUE(input.down[GLFW_KEY_W]);
  EXPECT_TRUE(input.pressed[GLFW_KEY_W]);
  EXPECT_TRUE(input.button_down[0]);
  EXPECT_TRUE(input.button_pressed[0]);
  EXPECT_EQ(input.mouse_dx, 0.0); // the first position is not a motion
  // Held: down, no new edge.
  tracker.cursor(13.0, 18.0);
  tracker.scroll(1.0);
  tracker.scroll(2.0);
  tracker.finish(input);
  EXPECT_TRUE(input.down[GLFW_KEY_W]);
  EXPECT_FALSE(input.pressed[GLFW_KEY_W]);
  EXPECT_FALSE(input.button_pressed[0]);
  EXPECT_EQ(input.mouse_dx, 3.0);
  EXPECT_EQ(input.mouse_dy, -2.0);
  EXPECT_EQ(input.scroll, 3.0);
  // Released; and a key tapped between two polls still reports its press.
  tracker.key(GLFW_KEY_W, false);
  tracker.button(0, false);
  tracker.key(GLFW_KEY_SPACE, true);
  tracker.key(GLFW_KEY_SPACE, false);
  tracker.key(-1, true); // GLFW_KEY_UNKNOWN: ignored
  tracker.finish(input);
  EXPECT_FALSE(input.down[GLFW_KEY_W]);
  EXPECT_TRUE(input.button_released[0]);
  EXPECT_FALSE(input.button_down[0]);
  EXPECT_TRUE(input.pressed[GLFW_KEY_SPACE]);
  EXPECT_FALSE(input.down[GLFW_KEY_SPACE]);
  EXPECT_EQ(input.scroll, 0.0);
  EXPECT_EQ(input.mouse_dx, 0.0);
  tracker.finish(input);
  EXPECT_FALSE(input.button_released[0]);
  EXPECT_FALSE(input.pressed[GLFW_KEY_SPACE]);
}

bool have_display() {
  const char* display = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  return (display != nullptr && *display != '\0') || (wayland != nullptr && *wayland != '\0');
}

#define SPECULA_NEED_DISPLAY()                                                                     \
  if (!have_display())                                                                             \
  GTEST_SKIP() << "no DISPLAY: the ctest entry Present.WindowUnderXvfb runs this under xvfb-run"

std::unique_ptr<Window> open_window(const WindowSettings& settings, std::string& why) {
  test::keep_vulkan_driver_loaded();
  try {
    return Window::open(settings);
  } catch (const UnavailableError& e) {
    why = e.what();
    return nullptr;
  }
}

TEST(Window, PresentsFramesAndReadsThemBack) {
  SPECULA_NEED_DISPLAY();
  WindowSettings settings;
  settings.width = 320;
  settings.height = 200;
  settings.ui = true;
  std::string why;
  auto window = open_window(settings, why);
  if (!window) GTEST_SKIP() << why;
  EXPECT_FALSE(window->device_name().empty());
  EXPECT_EQ(window->width(), 320u);
  EXPECT_EQ(window->height(), 200u);
  InputState input;
  // present() returns while the frame is still being presented (on a thread of its own): the
  // next present and a read-back wait for it. The first frames are read back one by one, the
  // later ones after a few presented back to back.
  for (std::uint32_t i = 0; i < 12; ++i) {
    const Framebuffer frame = random_frame(160 + 7 * i, 90 + 3 * i, 100 + i);
    ASSERT_TRUE(window->poll(input));
    const bool ui = i % 2 == 1;
    // A new ImGui window is laid out on its first frame and drawn from the next.
    for (int pass = 0; ui && pass < 2; ++pass) {
      window->begin_ui();
      ImGui::Begin("panel");
      ImGui::TextUnformatted("hello");
      ImGui::End();
      ImGui::Render();
    }
    window->present(frame, ui ? ImGui::GetDrawData() : nullptr);
    if (i >= 4 && i % 4 != 2 && i % 4 != 3) continue;
    const Rgba8Image shown = window->read_back();
    const Rgba8Image want = encode_srgb8(frame, window->width(), window->height());
    if (ui)
      EXPECT_FALSE(same_image(shown, want)) << "frame " << i << ": the panel is missing";
    else
      EXPECT_TRUE(same_image(shown, want)) << "frame " << i;
  }
}

TEST(Window, FollowsAResize) {
  SPECULA_NEED_DISPLAY();
  WindowSettings settings;
  settings.width = 320;
  settings.height = 200;
  std::string why;
  auto window = open_window(settings, why);
  if (!window) GTEST_SKIP() << why;
  const Framebuffer frame = random_frame(64, 40, 9);
  InputState input;
  window->poll(input);
  window->present(frame, nullptr);
  window->set_size(200, 240);
  // The X server applies the resize asynchronously; give it a moment (Xvfb: immediate).
  for (int i = 0; i < 100 && (window->width() != 200 || window->height() != 240); ++i) {
    window->poll(input);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(window->width(), 200u);
  ASSERT_EQ(window->height(), 240u);
  for (int i = 0; i < 2; ++i) window->present(frame, nullptr);
  EXPECT_TRUE(same_image(window->read_back(), encode_srgb8(frame, 200, 240)));
}

TEST(Window, WithoutADisplayOpeningThrowsWithTheReason) {
  // Both variables unset for the test only: GLFW reads them when it starts (at the first open).
  const char* display = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  const std::string saved_display = display ? display : "", saved_wayland = wayland ? wayland : "";
  ::unsetenv("DISPLAY");
  ::unsetenv("WAYLAND_DISPLAY");
  std::string what;
  try {
    (void)Window::open({});
  } catch (const UnavailableError& e) {
    what = e.what();
  }
  if (display) ::setenv("DISPLAY", saved_display.c_str(), 1);
  if (wayland) ::setenv("WAYLAND_DISPLAY", saved_wayland.c_str(), 1);
  EXPECT_NE(what.find("cannot open a window"), std::string::npos) << what;
  EXPECT_NE(what.find("DISPLAY"), std::string::npos) << what;
}

} // namespace
} // namespace specula::present
