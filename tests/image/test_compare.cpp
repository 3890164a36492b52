// `specula compare` (editor/compare_command.cpp), run in-process: output formats, heatmap,
// and errors naming the files.

#include "compare_command.h"
#include "specula/core/error.h"
#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/metrics.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>

namespace specula {
namespace {

using cli::CompareOptions;
using cli::run_compare;

std::string compare_output(const CompareOptions& options) {
  std::ostringstream out;
  EXPECT_EQ(run_compare(options, out), 0);
  return out.str();
}

TEST(Compare, IdenticalImagesPrintZeroInfiniteAndZero) {
  test::TempDir dir;
  write_png(test::random_image(16, 16, 81), dir.file("a.png"));
  const CompareOptions options{dir.file("a.png").string(), dir.file("a.png").string(), "", false};
  EXPECT_EQ(compare_output(options), "RMSE 0\nPSNR inf dB\nFLIP 0\n");
}

TEST(Compare, PrintsTheMetricsOfTheDecodedImages) {
  test::TempDir dir;
  write_png(test::random_image(32, 24, 82), dir.file("a.png"));
  write_png(test::random_image(32, 24, 83), dir.file("b.png"));
  const std::string text =
      compare_output({dir.file("a.png").string(), dir.file("b.png").string(), "", false});

  // What compare prints is what the library computes on the decoded files.
  const Framebuffer a = read_png(dir.file("a.png"));
  const Framebuffer b = read_png(dir.file("b.png"));
  std::istringstream in(text);
  std::string label;
  std::string unit;
  double printed_rmse = 0.0;
  double printed_psnr = 0.0;
  double printed_flip = 0.0;
  in >> label >> printed_rmse;
  EXPECT_EQ(label, "RMSE");
  in >> label >> printed_psnr >> unit;
  EXPECT_EQ(label, "PSNR");
  EXPECT_EQ(unit, "dB");
  in >> label >> printed_flip;
  EXPECT_EQ(label, "FLIP");
  EXPECT_NEAR(printed_rmse, rmse(a, b), 1e-5 * rmse(a, b));
  EXPECT_NEAR(printed_psnr, psnr(a, b), 1e-4);
  EXPECT_NEAR(printed_flip, flip(a, b).mean, 1e-5);
  EXPECT_GT(printed_flip, 0.0);
}

TEST(Compare, JsonAndHeatmap) {
  test::TempDir dir;
  const Framebuffer a = test::random_image(20, 20, 84);
  write_exr(a, dir.file("a.exr"));
  write_exr(a, dir.file("same.exr"));
  write_exr(test::random_image(20, 20, 85), dir.file("b.exr"));

  const std::string same =
      compare_output({dir.file("a.exr").string(), dir.file("same.exr").string(), "", true});
  EXPECT_EQ(same, "{\"rmse\": 0, \"psnr_db\": null, \"flip_mean\": 0}\n");

  const auto heatmap = dir.file("heat.png");
  const std::string json = compare_output(
      {dir.file("a.exr").string(), dir.file("b.exr").string(), heatmap.string(), true});
  EXPECT_NE(json.find("\"rmse\": 0."), std::string::npos) << json;
  EXPECT_NE(json.find("\"psnr_db\": "), std::string::npos) << json;
  EXPECT_EQ(json.find("null"), std::string::npos) << json;
  EXPECT_NE(json.find("\"flip_mean\": 0."), std::string::npos) << json;
  const Framebuffer heat = read_png(heatmap);
  EXPECT_EQ(heat.width(), 20u);
  EXPECT_EQ(heat.height(), 20u);
}

TEST(Compare, SizeMismatchNamesBothFilesAndSizes) {
  test::TempDir dir;
  write_png(Framebuffer(16, 8), dir.file("wide.png"));
  write_png(Framebuffer(8, 16), dir.file("tall.png"));
  std::ostringstream out;
  try {
    run_compare({dir.file("wide.png").string(), dir.file("tall.png").string(), "", false}, out);
    FAIL() << "no error";
  } catch (const Error& e) {
    const std::string what = e.what();
    for (const char* needle : {"wide.png", "tall.png", "16x8", "8x16"}) {
      EXPECT_NE(what.find(needle), std::string::npos) << needle << " missing in: " << what;
    }
  }
  EXPECT_TRUE(out.str().empty());
}

TEST(Compare, UnreadableInputNamesTheFile) {
  test::TempDir dir;
  write_png(Framebuffer(4, 4), dir.file("a.png"));
  std::ostringstream out;
  try {
    run_compare({dir.file("a.png").string(), dir.file("nothere.png").string(), "", false}, out);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nothere.png"), std::string::npos) << e.what();
  }
  EXPECT_THROW(
      run_compare({dir.file("a.png").string(), dir.file("a.tiff").string(), "", false}, out),
      Error);
}

} // namespace
} // namespace specula
