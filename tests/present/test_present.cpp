// Presentation (engine/present): the CPU encoding against the PNG writer, the offscreen target
// against the CPU encoding (with and without Dear ImGui over the frame), the window under a
// display (Xvfb in CI), and the input bookkeeping behind Window::poll.
#include "../gpu/device_scenes.h"
#include "specula/core/error.h"
#include "specula/gpu/device_renderer.h"
#include "specula/gpu/vk_context.h"
#include "specula/image/image_io.h"
#include "specula/image/srgb.h"
#include "specula/present/input.h"
#include "specula/present/window.h"
#include "specula/render/tracer_factory.h"
#include "specula/trace/render_frame.h"

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

/// `frame` on `context`'s device as a device frame's buffer: one vec4 per pixel.
gpu::Buffer device_copy(gpu::Context& context, const Framebuffer& frame) {
  std::vector<glm::vec4> pixels;
  for (const vec3& p : frame.pixels()) pixels.emplace_back(p, 0.0f);
  gpu::Buffer buffer = context.make_buffer(pixels.size() * sizeof(glm::vec4));
  buffer.upload(pixels.data(), pixels.size() * sizeof(glm::vec4));
  return buffer;
}

/// Every channel within one code of the wanted one (bilinear scaling: the host may fuse a
/// multiply-add the kernel keeps apart), and no more than 1% of them off at all.
::testing::AssertionResult within_one_code(const Rgba8Image& got, const Rgba8Image& want) {
  if (got.width != want.width || got.height != want.height) return same_image(got, want);
  std::size_t off = 0;
  for (std::size_t i = 0; i < want.rgba.size(); ++i) {
    const int d = int(got.rgba[i]) - int(want.rgba[i]);
    if (d < -1 || d > 1)
      return ::testing::AssertionFailure()
             << "byte " << i << ": " << int(got.rgba[i]) << ", want " << int(want.rgba[i]);
    off += d != 0 ? 1 : 0;
  }
  if (off * 100 > want.rgba.size())
    return ::testing::AssertionFailure() << off << " bytes one code off";
  return ::testing::AssertionSuccess();
}

/// A frame whose values sit on both sides of every step of the 8-bit encoding (each threshold
/// and the float below it), then the values the clamp handles: -0, ±inf, NaN, above 1.
Framebuffer threshold_frame() {
  Framebuffer frame(64, 8);
  const Srgb8Encoder& encoder = Srgb8Encoder::get();
  std::span<vec3> px = frame.pixels();
  for (std::uint32_t k = 1; k < 256; ++k) {
    const float t = encoder.threshold(k);
    px[2 * (k - 1)] = vec3(t, std::nextafter(t, 0.0f), t);
    px[2 * (k - 1) + 1] = vec3(std::nextafter(t, 0.0f), t, std::nextafter(t, 2.0f));
  }
  const float inf = std::numeric_limits<float>::infinity();
  px[510] = vec3(-0.0f, inf, -inf);
  px[511] = vec3(std::numeric_limits<float>::quiet_NaN(), 1.0f, 1.5f);
  return frame;
}

TEST(Offscreen, DeviceFramesDrawTheBytesOfTheHostEncoding) {
  const Framebuffer random = random_frame(37, 23, 5), steps = threshold_frame();
  struct Case {
    const Framebuffer* frame;
    std::uint32_t width, height;
    bool bilinear;
  };
  // The same size, smaller with bars (nearest neighbour), larger (bilinear), letterboxed.
  for (const Case& c :
       {Case{&steps, 64, 8, false}, Case{&random, 37, 23, false}, Case{&random, 30, 41, false},
        Case{&random, 64, 48, true}, Case{&steps, 160, 40, true}}) {
    auto target = try_offscreen({c.width, c.height, false});
    if (!target) GTEST_SKIP() << "no Vulkan device on this machine";
    const gpu::Buffer buffer = device_copy(*target->context(), *c.frame);
    const gpu::DeviceFrame frame{target->context().get(), &buffer, c.frame->width(),
                                 c.frame->height()};
    const Rgba8Image shown = target->render(frame, nullptr);
    const Rgba8Image want = encode_srgb8(*c.frame, c.width, c.height);
    if (c.bilinear)
      EXPECT_TRUE(within_one_code(shown, want)) << c.width << "x" << c.height;
    else
      EXPECT_TRUE(same_image(shown, want)) << c.width << "x" << c.height;
  }
}

TEST(Offscreen, RefusesADeviceFrameOfAnotherDevice) {
  auto target = try_offscreen({8, 8, false});
  if (!target) GTEST_SKIP() << "no Vulkan device on this machine";
  const auto other = gpu::Context::create();
  const Framebuffer frame = random_frame(8, 8, 3);
  const gpu::Buffer buffer = device_copy(*other, frame);
  EXPECT_THROW((void)target->render(gpu::DeviceFrame{other.get(), &buffer, 8, 8}, nullptr),
               std::invalid_argument);
  // A buffer too small for the size it claims.
  const gpu::Buffer mine = device_copy(*target->context(), frame);
  EXPECT_THROW(
      (void)target->render(gpu::DeviceFrame{target->context().get(), &mine, 8, 9}, nullptr),
      std::invalid_argument);
}

/// A Vulkan tracer on `device` over the test Cornell box, its frames kept on the device.
struct SharedTracer {
  ecs::Registry reg;
  std::unique_ptr<test::TracedWorld> world;
  explicit SharedTracer(std::shared_ptr<gpu::Context> device) {
    test::cornell(reg);
    TracerOptions options;
    options.gpu.device = std::move(device);
    world = std::make_unique<test::TracedWorld>(reg, "vulkan", options);
  }
  Tracer& tracer() { return *world->tracer; }
  FrameStats render(TraceMode mode, Framebuffer& out,
                    const Camera& camera = test::cornell_camera()) {
    TraceSettings s;
    s.mode = mode;
    s.max_depth = 4;
    s.threads = 2;
    return render_frame(*world->tracer, world->layer, camera, s, out, nullptr);
  }
};

TEST(Offscreen, ShowsAVulkanTracersFrameWhereItIs) {
  constexpr std::uint32_t kW = 64, kH = 48;
  auto target = try_offscreen({kW, kH, false});
  if (!target) GTEST_SKIP() << "no Vulkan device on this machine";
  SharedTracer shared(target->context());
  ASSERT_TRUE(keep_frames_on_device(shared.tracer(), true));
  ASSERT_EQ(tracer_device(shared.tracer())->name, target->context()->info().name);

  const Framebuffer untouched(kW, kH, vec3(0.5f, -1.0f, 7.0f));
  Framebuffer out = untouched;
  shared.render(TraceMode::Whitted, out);
  EXPECT_EQ(out, untouched) << "the frame went through the host";
  const gpu::DeviceFrame* on_device = device_frame(shared.tracer());
  ASSERT_NE(on_device, nullptr);
  EXPECT_EQ(on_device->context, target->context().get());
  EXPECT_EQ(on_device->width, kW);
  const Rgba8Image shown = target->render(*on_device, nullptr);

  // Read back on demand, the frame is the one shown, and the one a frame read back at once is.
  Framebuffer host(kW, kH);
  read_back_frame(shared.tracer(), host);
  EXPECT_EQ(device_frame(shared.tracer()), nullptr) << "read back: no longer on the device only";
  EXPECT_THROW(read_back_frame(shared.tracer(), host), Error);
  EXPECT_TRUE(same_image(shown, encode_srgb8(host, kW, kH)));
  ASSERT_TRUE(keep_frames_on_device(shared.tracer(), false));
  Framebuffer direct(kW, kH);
  shared.render(TraceMode::Whitted, direct);
  EXPECT_EQ(device_frame(shared.tracer()), nullptr);
  EXPECT_EQ(direct, host);
  EXPECT_NE(direct, untouched);

  // Path frames are averaged on the host: read back even when kept.
  ASSERT_TRUE(keep_frames_on_device(shared.tracer(), true));
  out = untouched;
  shared.render(TraceMode::Path, out);
  EXPECT_EQ(device_frame(shared.tracer()), nullptr);
  EXPECT_NE(out, untouched);

  // CPU tracers have no device to keep frames on.
  test::TracedWorld cpu(shared.reg, "native");
  EXPECT_FALSE(keep_frames_on_device(*cpu.tracer, true));
  EXPECT_EQ(device_frame(*cpu.tracer), nullptr);
  EXPECT_THROW(read_back_frame(*cpu.tracer, host), Error);
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

/// A 320×200 window with Dear ImGui (null, with the reason in `why`, when none opens).
std::unique_ptr<Window> open_ui_window(std::string& why) {
  WindowSettings settings;
  settings.width = 320;
  settings.height = 200;
  settings.ui = true;
  return open_window(settings, why);
}

/// One panel's draw data for the next present.
ImDrawData* panel_ui(Window& window) {
  // A new ImGui window is laid out on its first frame and drawn from the next.
  for (int pass = 0; pass < 2; ++pass) {
    window.begin_ui();
    ImGui::Begin("panel");
    ImGui::TextUnformatted("hello");
    ImGui::End();
    ImGui::Render();
  }
  return ImGui::GetDrawData();
}

TEST(Window, PresentsFramesAndReadsThemBack) {
  SPECULA_NEED_DISPLAY();
  std::string why;
  auto window = open_ui_window(why);
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
    window->present(frame, ui ? panel_ui(*window) : nullptr);
    if (i >= 4 && i % 4 != 2 && i % 4 != 3) continue;
    const Rgba8Image shown = window->read_back();
    const Rgba8Image want = encode_srgb8(frame, window->width(), window->height());
    if (ui)
      EXPECT_FALSE(same_image(shown, want)) << "frame " << i << ": the panel is missing";
    else
      EXPECT_TRUE(same_image(shown, want)) << "frame " << i;
  }
}

TEST(Window, PresentsAVulkanTracersFramesWhereTheyAre) {
  SPECULA_NEED_DISPLAY();
  std::string why;
  auto window = open_ui_window(why);
  if (!window) GTEST_SKIP() << why;
  SharedTracer shared(window->context());
  ASSERT_TRUE(keep_frames_on_device(shared.tracer(), true));
  InputState input;
  Camera camera = test::cornell_camera();
  // Frames presented back to back while the next renders on the same queue (the present runs on
  // a thread of its own), at the window's size and smaller (scaled up), with and without panels;
  // some read back and compared with the host encoding of the frame read back.
  for (std::uint32_t i = 0; i < 8; ++i) {
    const bool small = i % 3 == 1;
    Framebuffer out(small ? 160 : 320, small ? 100 : 200);
    camera.position.x = 0.05 * i;
    shared.render(TraceMode::Whitted, out, camera);
    const gpu::DeviceFrame* on_device = device_frame(shared.tracer());
    ASSERT_NE(on_device, nullptr) << "frame " << i;
    ASSERT_TRUE(window->poll(input));
    const bool ui = i % 4 == 3;
    window->present(*on_device, ui ? panel_ui(*window) : nullptr);
    if (i % 2 == 0) continue;
    const Rgba8Image shown = window->read_back();
    read_back_frame(shared.tracer(), out);
    const Rgba8Image want = encode_srgb8(out, window->width(), window->height());
    if (ui)
      EXPECT_FALSE(same_image(shown, want)) << "frame " << i << ": the panel is missing";
    else if (small)
      EXPECT_TRUE(within_one_code(shown, want)) << "frame " << i;
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
