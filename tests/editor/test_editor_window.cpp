// The editor window's input mapping (editor/window_controls.h), fed made-up polls: no display
// needed. A click at a window pixel selects what the frame shows there (through the letterbox),
// an X-held drag of one unit's window vector (two mouse moves) moves the selection by one unit
// as one undo step, Ctrl+Z / Ctrl+Y undo and redo it, input a panel holds is ignored, a right drag orbits.

#include "editor/window_controls.h"
#include "editor_test_util.h"

#include <GLFW/glfw3.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

namespace specula::editor {
namespace {

namespace fs = std::filesystem;

const fs::path kScenes = fs::path(SPECULA_SOURCE_DIR) / "samples" / "scenes";

// A 96x72 frame in a 240x144 window: scale 2, pillars of 24 pixels left and right.
constexpr std::uint32_t kFrameW = 96, kFrameH = 72, kWindowW = 240, kWindowH = 144;
constexpr double kScale = 2.0, kPillar = 24.0;

ViewSettings view() {
  ViewSettings v;
  v.backend = "native";
  v.mode = TraceMode::Whitted;
  v.width = kFrameW;
  v.height = kFrameH;
  v.max_depth = 2;
  return v;
}

dvec2 pixel_of(const Camera& c, const dvec3& p) {
  return test::pixel_of(c, kFrameW, kFrameH, p);
}

dvec2 window_of(const dvec2& frame_pixel) {
  return dvec2(kPillar + kScale * frame_pixel.x, kScale * frame_pixel.y);
}

/// One poll with the mouse at `at` (window pixels), moved from `from`.
present::InputState poll_at(const dvec2& at, const dvec2& from) {
  present::InputState in;
  in.mouse_x = at.x;
  in.mouse_y = at.y;
  in.mouse_dx = at.x - from.x;
  in.mouse_dy = at.y - from.y;
  return in;
}

void apply(WindowControls& c, EditorSession& s, const present::InputState& in) {
  c.apply(s, in, kWindowW, kWindowH);
}

/// Presses `key` (with Ctrl held when asked) in one poll and releases it in the next.
void tap(WindowControls& c, EditorSession& s, int key, bool ctrl = false) {
  present::InputState in;
  in.down[std::size_t(key)] = in.pressed[std::size_t(key)] = true;
  if (ctrl) in.down[GLFW_KEY_LEFT_CONTROL] = true;
  apply(c, s, in);
  apply(c, s, present::InputState{});
}

/// Left button down at `at`, up again in the next poll, the mouse still.
void click(WindowControls& c, EditorSession& s, const dvec2& at) {
  present::InputState down = poll_at(at, at);
  down.button_down[0] = down.button_pressed[0] = true;
  apply(c, s, down);
  present::InputState up = poll_at(at, at);
  up.button_released[0] = true;
  apply(c, s, up);
}

ecs::Entity named(EditorSession& s, const std::string& name) {
  s.select_by_name(name);
  return *s.selected();
}

TEST(EditorWindow, WindowPixelsMapThroughTheLetterboxToFramePixels) {
  const auto p =
      window_to_frame(kWindowW, kWindowH, kFrameW, kFrameH, kPillar + 2.0 * 10.25, 2.0 * 30.5);
  ASSERT_TRUE(p);
  EXPECT_DOUBLE_EQ(p->x, 10.25);
  EXPECT_DOUBLE_EQ(p->y, 30.5);
  EXPECT_FALSE(window_to_frame(kWindowW, kWindowH, kFrameW, kFrameH, kPillar - 1.0, 10.0))
      << "left pillar";
  EXPECT_FALSE(
      window_to_frame(kWindowW, kWindowH, kFrameW, kFrameH, kWindowW - kPillar + 0.5, 10.0))
      << "right pillar";
  EXPECT_FALSE(window_to_frame(kWindowW, kWindowH, kFrameW, kFrameH, 100.0, -0.5))
      << "above the window";
  EXPECT_FALSE(window_to_frame(0, 0, kFrameW, kFrameH, 0.0, 0.0)) << "a minimised window";
}

TEST(EditorWindow, ClickSelectsXDragMovesOneUnitCtrlZUndoesCtrlYRedoes) {
  EditorSession s(kScenes / "cornell_box.json", view());
  s.tick();
  const ecs::Entity sphere = named(s, "mirror sphere");
  s.clear_selection();
  WindowControls c;
  const Camera cam = s.camera();
  const dvec3 p = dvec3(s.registry().get<WorldTransform>(sphere).world_from_object[3]);
  const dvec2 at = window_of(pixel_of(cam, p));

  click(c, s, at);
  ASSERT_EQ(s.selected(), std::optional<ecs::Entity>(sphere)) << "a click picks what it shows";
  const Transform t0 = s.registry().get<Transform>(sphere);
  const std::size_t depth0 = s.undo_depth();

  // X held, left button down, the mouse moved by one unit's window vector in two polls.
  const dvec2 to = window_of(pixel_of(cam, p + dvec3(1, 0, 0)));
  present::InputState in = poll_at(at, at);
  in.down[GLFW_KEY_X] = true;
  in.button_down[0] = in.button_pressed[0] = true;
  apply(c, s, in);
  const dvec2 mid = 0.5 * (at + to);
  for (const auto& [from, next] : {std::pair{at, mid}, std::pair{mid, to}}) {
    in = poll_at(next, from);
    in.down[GLFW_KEY_X] = in.button_down[0] = true;
    apply(c, s, in);
  }
  in = poll_at(to, to);
  in.button_released[0] = true;
  apply(c, s, in);
  EXPECT_EQ(s.selected(), std::optional<ecs::Entity>(sphere)) << "a drag's release is no click";
  const Transform t1 = s.registry().get<Transform>(sphere);
  EXPECT_NEAR(t1.translation.x - t0.translation.x, 1.0, 1e-5);
  EXPECT_NEAR(t1.translation.y, t0.translation.y, 1e-9);
  EXPECT_NEAR(t1.translation.z, t0.translation.z, 1e-9);
  EXPECT_TRUE(c.status().empty()) << c.status();
  EXPECT_EQ(s.undo_depth(), depth0 + 1) << "one drag, however many mouse moves, is one undo step";

  tap(c, s, GLFW_KEY_Z, /*ctrl=*/true);
  EXPECT_EQ(s.registry().get<Transform>(sphere).translation, t0.translation) << "Ctrl+Z";
  tap(c, s, GLFW_KEY_Y, /*ctrl=*/true);
  EXPECT_EQ(s.registry().get<Transform>(sphere).translation, t1.translation) << "Ctrl+Y";
  tap(c, s, GLFW_KEY_Z);
  EXPECT_EQ(s.registry().get<Transform>(sphere).translation, t1.translation)
      << "Z without Ctrl is no undo";
}

TEST(EditorWindow, InputAPanelHoldsIsIgnored) {
  EditorSession s(kScenes / "cornell_box.json", view());
  s.tick();
  const ecs::Entity sphere = named(s, "mirror sphere");
  s.clear_selection();
  WindowControls c;
  const dvec2 at = window_of(pixel_of(
      s.camera(), dvec3(s.registry().get<WorldTransform>(sphere).world_from_object[3])));
  present::InputState in = poll_at(at, at);
  in.ui_wants_mouse = true;
  in.button_down[0] = in.button_pressed[0] = true;
  apply(c, s, in);
  in = poll_at(at, at);
  in.ui_wants_mouse = true;
  in.button_released[0] = true;
  apply(c, s, in);
  EXPECT_EQ(s.selected(), std::nullopt) << "the click went to a panel";

  s.select(sphere);
  in = present::InputState{};
  in.ui_wants_keyboard = true;
  in.down[GLFW_KEY_DELETE] = in.pressed[GLFW_KEY_DELETE] = true;
  apply(c, s, in);
  EXPECT_TRUE(s.registry().valid(sphere)) << "Delete typed into a text field deletes nothing";
  apply(c, s, present::InputState{});
  tap(c, s, GLFW_KEY_DELETE);
  EXPECT_FALSE(s.registry().valid(sphere)) << "Delete with the viewport's focus does";
}

TEST(EditorWindow, RightDragOrbitsAtTheSameDistanceAndGizmoKeysSwitchMode) {
  EditorSession s(kScenes / "cornell_box.json", view());
  s.tick();
  WindowControls c;
  const Camera before = s.camera();
  present::InputState in = poll_at(dvec2(120, 70), dvec2(100, 70));
  in.button_down[1] = true;
  apply(c, s, in);
  const Camera after = s.camera();
  EXPECT_GT(glm::length(after.position - before.position), 1e-3) << "the camera moved";
  EXPECT_NEAR(glm::length(after.position - after.look_at),
              glm::length(before.position - before.look_at), 1e-9);
  EXPECT_EQ(c.gizmo(), GizmoMode::Translate);
  tap(c, s, GLFW_KEY_R);
  EXPECT_EQ(c.gizmo(), GizmoMode::Rotate);
  tap(c, s, GLFW_KEY_T);
  EXPECT_EQ(c.gizmo(), GizmoMode::Scale);
  tap(c, s, GLFW_KEY_G);
  EXPECT_EQ(c.gizmo(), GizmoMode::Translate);
}

} // namespace
} // namespace specula::editor
