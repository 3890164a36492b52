// `specula render` in-process: the progress line a long render shows on a terminal, and nothing
// on a pipe or for a short render.

#include "commands.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>

namespace specula::cli {
namespace {

RenderOptions options(std::uint32_t frames, std::uint32_t size, double progress_after_s) {
  RenderOptions o;
  o.progress_after_s = progress_after_s;
  o.scene =
      (std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  o.frames = frames;
  o.width = size;
  o.height = size;
  o.threads = 1;
  return o;
}

TEST(RenderCommand, ALongRenderShowsItsProgressOnATerminal) {
  // The program shows progress after a second; the test lowers that to 20 ms and renders a few
  // hundred milliseconds' worth of frames.
  std::ostringstream out, progress;
  ASSERT_EQ(run_render(options(400, 32, 0.02), out, &progress, true), 0);
  const std::string p = progress.str();
  ASSERT_NE(p.find("frames/s"), std::string::npos) << "no progress after more than a second";
  EXPECT_NE(p.find("/400,"), std::string::npos) << p.substr(0, 200);
  EXPECT_NE(p.find("s left"), std::string::npos);
  EXPECT_EQ(p.find('\n'), std::string::npos) << "progress rewrites one line in place";
  EXPECT_EQ(p.back(), '\r') << "the line is cleared when the render ends";
  EXPECT_NE(out.str().find("400 frame(s)"), std::string::npos);
}

TEST(RenderCommand, NoProgressOffATerminalOrForAShortRender) {
  std::ostringstream out, progress;
  ASSERT_EQ(run_render(options(400, 32, 0.02), out, &progress, false), 0);
  EXPECT_TRUE(progress.str().empty());
  std::ostringstream out2, progress2;
  ASSERT_EQ(run_render(options(2, 32, 1.0), out2, &progress2, true), 0);
  EXPECT_TRUE(progress2.str().empty()) << "a render under the threshold shows none";
}

} // namespace
} // namespace specula::cli
