// Runs the `specula` program as a user would: exit codes (0 ok, 1 bad input, 2 unavailable),
// messages naming the file, and no crash on any input.

#include "specula/render/tracer_factory.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

namespace fs = std::filesystem;

struct Result {
  bool exited = false; ///< false: killed by a signal
  int code = -1;
  std::string out;
  std::string err;
};

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string quote(const std::string& s) {
  std::string q = "'";
  for (const char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

/// Runs the program with `args`; `shell_prefix` runs first in the same shell (limits, traps) and
/// the program replaces the shell (exec), so its exit status is the program's.
Result run(const std::vector<std::string>& args, const std::string& shell_prefix = "") {
  static int counter = 0;
  const fs::path dir = fs::temp_directory_path();
  const std::string tag = std::to_string(::getpid()) + "_" + std::to_string(counter++);
  const fs::path out = dir / ("specula_cli_out_" + tag);
  const fs::path err = dir / ("specula_cli_err_" + tag);
  std::string cmd =
      shell_prefix.empty() ? quote(SPECULA_EXE) : shell_prefix + "; exec " + quote(SPECULA_EXE);
  for (const auto& a : args) cmd += " " + quote(a);
  cmd += " >" + quote(out.string()) + " 2>" + quote(err.string()) + " </dev/null";
  const int status = std::system(cmd.c_str());
  Result r;
  // std::system runs /bin/sh: a program killed by signal N shows as sh exit code 128 + N.
  r.exited = WIFEXITED(status) && WEXITSTATUS(status) < 128;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = slurp(out);
  r.err = slurp(err);
  fs::remove(out);
  fs::remove(err);
  return r;
}

std::vector<fs::path> files_under(const fs::path& dir, const std::set<std::string>& extensions) {
  std::vector<fs::path> files;
  if (!fs::is_directory(dir)) return files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (extensions.count(ext)) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

const std::set<std::string> kSceneExtensions = {".json", ".gltf", ".glb", ".obj",
                                                ".ply",  ".off",  ".stl"};

TEST(Cli, InfoWorksOnEverySampleScene) {
  const auto scenes =
      files_under(fs::path(SPECULA_SOURCE_DIR) / "samples/scenes", {".json", ".gltf", ".glb"});
  ASSERT_GE(scenes.size(), 9u) << "cornell_box, 7 mirror_spheres scenes and a glTF scene";
  for (const auto& scene : scenes) {
    const Result r = run({"info", "--json", scene.string()});
    ASSERT_TRUE(r.exited) << scene;
    EXPECT_EQ(r.code, 0) << scene << "\n" << r.err;
    const auto j = nlohmann::json::parse(r.out, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << r.out;
    EXPECT_GT(j.at("triangles").get<long>(), 0) << scene;
    EXPECT_GE(j.at("lights").get<long>() + j.at("emissive_meshes").get<long>(), 1) << scene;
    EXPECT_EQ(j.at("cameras").get<long>(), 1) << scene;
    EXPECT_TRUE(j.contains("bounds")) << scene;
  }
}

TEST(Cli, MirrorSpheresFamilyHasOnePlusNReflectiveSpheres) {
  for (const int n : {0, 1, 2, 4, 8, 16, 32}) {
    const fs::path scene = fs::path(SPECULA_SOURCE_DIR) /
                           ("samples/scenes/mirror_spheres_" + std::to_string(n) + ".json");
    const Result r = run({"info", "--json", scene.string()});
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j.at("reflective").get<int>(), n + 1) << scene;
    EXPECT_EQ(j.at("lights").get<int>(), 1) << scene;
    EXPECT_EQ(j.at("settings").at("width").get<int>(), 1024) << scene;
    EXPECT_EQ(j.at("settings").at("height").get<int>(), 1024) << scene;
  }
}

TEST(Cli, InfoPrintsCountsAndBounds) {
  const Result r =
      run({"info", (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string()});
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* word : {"entities:", "triangles:", "materials:", "lights:", "bounds:"})
    EXPECT_NE(r.out.find(word), std::string::npos) << word << "\n" << r.out;
}

TEST(Cli, MissingFileExitsOneNamingIt) {
  const Result r = run({"info", "/no/such/scene.json"});
  ASSERT_TRUE(r.exited);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("/no/such/scene.json"), std::string::npos) << r.err;
}

TEST(Cli, BadOptionsExitOne) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  for (const std::vector<std::string>& args :
       std::vector<std::vector<std::string>>{{"render", scene, "--backend", "optix"},
                                             {"render", scene, "--mode", "radiosity"},
                                             {"render", scene, "--width", "0"},
                                             {"render", scene, "--height", "100000"},
                                             {"render", scene, "--frames", "0"},
                                             {"render", scene, "--time", "2:1"},
                                             {"render", scene, "--cache", "100"},
                                             {"render", scene, "--cache", "-4"},
                                             {"render", scene, "--cache", "sometimes"},
                                             {"render", scene, "--cache", "on", "--cache-lookup", "guess"},
                                             {"render", scene, "--cache", "on", "--cache-tau", "0"},
                                             {"render", scene, "--cache", "on", "--cache-tau", "nan"},
                                             {"render", scene, "--cache", "on", "--cache-resolution", "48"},
                                             {"render", scene, "--cache", "auto", "--max-error-db", "-3"},
                                             {"render", scene, "--width", "abc"},
                                             {"render"},
                                             {"frobnicate"},
                                             {}}) {
    const Result r = run(args);
    ASSERT_TRUE(r.exited);
    std::string joined;
    for (const auto& a : args) joined += a + " ";
    EXPECT_EQ(r.code, 1) << joined << "\n" << r.err;
    EXPECT_FALSE(r.err.empty()) << joined;
  }
}

TEST(Cli, BadSamplingOptionsExitOneNamingTheOption) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  struct Case {
    std::vector<std::string> extra;
    std::string said; ///< in the message
  };
  const std::string spp = "--spp: expected a whole number in [1 - 65536]";
  const std::string shadow = "--shadow-samples: expected a whole number in [1 - 4096]";
  const std::string seed = "--seed: expected a whole number in [0 - 4294967295]";
  for (const Case& c : std::vector<Case>{
           {{"--mode", "path", "--spp", "0"}, spp + ", got 0"},
           {{"--mode", "path", "--spp", "65537"}, spp},
           {{"--mode", "path", "--spp", "1.5"}, "--spp: expected a whole number"},
           {{"--mode", "path", "--spp", "many"}, "--spp: expected a number"},
           {{"--mode", "shadow", "--shadow-samples", "0"}, shadow},
           {{"--mode", "shadow", "--shadow-samples", "4097"}, shadow},
           {{"--mode", "path", "--sampling", "foo"},
            "--sampling: expected one of mis, bsdf, light, got 'foo'"},
           {{"--mode", "path", "--seed", "-1"}, seed},
           {{"--mode", "path", "--seed", "4294967296"}, seed},
           {{"--mode", "path", "--accumulate", "maybe"},
            "--accumulate: expected one of on, off, got 'maybe'"},
           {{"--mode", "whitted", "--denoise"},
            "--denoise: filters the noise of --mode path and shadow"},
           {{"--mode", "cast", "--denoise"}, "mode 'cast' has none"}}) {
    std::vector<std::string> args = {"render", scene, "--width", "8", "--height", "8"};
    args.insert(args.end(), c.extra.begin(), c.extra.end());
    const Result r = run(args);
    ASSERT_TRUE(r.exited);
    EXPECT_EQ(r.code, 1) << c.said << "\n" << r.err;
    EXPECT_EQ(r.err.rfind("specula: error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(c.said), std::string::npos) << r.err;
  }
}

/// The CPU backends this build has.
std::vector<std::string> cpu_backends() {
  std::vector<std::string> names;
  for (const specula::BackendInfo& b : specula::backends())
    if (b.available && (b.name == "embree" || b.name == "native")) names.emplace_back(b.name);
  return names;
}

TEST(Cli, RenderWritesTheImageAndStatsOnEveryCpuBackend) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  const fs::path dir =
      fs::temp_directory_path() / ("specula_cli_render_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  for (const std::string& backend : cpu_backends())
  for (const char* mode : {"cast", "whitted"}) {
    SCOPED_TRACE(backend);
    const fs::path png = dir / (std::string(mode) + ".png");
    const fs::path stats = dir / (std::string(mode) + ".json");
    const Result r = run({"render", scene, "--backend", backend, "--mode", mode, "--width", "48",
                          "--height", "32", "--frames", "2", "--threads", "1", "--out",
                          png.string(), "--stats", stats.string()});
    ASSERT_TRUE(r.exited);
    ASSERT_EQ(r.code, 0) << mode << "\n" << r.err;
    EXPECT_GT(fs::file_size(png), 0u);
    const auto j = nlohmann::json::parse(slurp(stats));
    ASSERT_EQ(j.at("frames").size(), 2u);
    EXPECT_EQ(j.at("frames").at(0).at("rays").at("primary").get<long>(), 48 * 32);
    EXPECT_EQ(j.at("settings").at("mode"), mode);
    EXPECT_EQ(j.at("settings").at("width"), 48);
    if (std::string(mode) == "cast") {
      EXPECT_EQ(j.at("frames").at(0).at("rays").at("shadow").get<long>(), 0);
    } else {
      EXPECT_GT(j.at("frames").at(0).at("rays").at("shadow").get<long>(), 0);
    }
  }
  // compare: an image against itself is exact.
  const Result same =
      run({"compare", (dir / "cast.png").string(), (dir / "cast.png").string(), "--json"});
  ASSERT_EQ(same.code, 0) << same.err;
  EXPECT_EQ(nlohmann::json::parse(same.out).at("rmse").get<double>(), 0.0);
  const Result differ =
      run({"compare", (dir / "cast.png").string(), (dir / "whitted.png").string()});
  ASSERT_EQ(differ.code, 0) << differ.err;
  EXPECT_NE(differ.out.find("PSNR"), std::string::npos);
  fs::remove_all(dir);
}

/// Runs with no Vulkan device for the backend: SPECULA_VK_DEVICE names none of the devices.
const char* const kNoVulkanDevice = "export SPECULA_VK_DEVICE=no-such-device";
/// Runs with no Vulkan driver at all: the loader finds no ICD.
const char* const kNoVulkanDriver = "export VK_ICD_FILENAMES=/nonexistent/icd.json";

/// Whether this build has the backend (available on this machine or not).
bool in_this_build(const char* backend) {
  return specula::backend_info(backend).reason.find("not in this build") == std::string::npos;
}

/// Whether the message is one line (plus its newline).
bool one_line_message(const std::string& text) {
  return !text.empty() && text.back() == '\n' && text.find('\n') == text.size() - 1;
}

TEST(Cli, BackendsNotAvailableExitTwo) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  std::vector<std::string> unavailable;
  if (!specula::backend_info("embree").available) unavailable.push_back("embree");
  if (!specula::backend_info("vulkan").available) unavailable.push_back("vulkan");
  for (const std::string& backend : unavailable) {
    const Result r =
        run({"render", scene, "--width", "16", "--height", "16", "--backend", backend});
    ASSERT_TRUE(r.exited);
    EXPECT_EQ(r.code, 2) << backend << "\n" << r.err;
    EXPECT_NE(r.err.find("specula: not available: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(backend), std::string::npos)
        << "the message names what is missing: " << r.err;
  }
}

TEST(Cli, ForcedVulkanBackendWithoutADeviceExitsTwoWithOneLineSayingWhy) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  for (const char* backend : {"vulkan", "vulkan-grid"})
    for (const char* forced : {kNoVulkanDevice, kNoVulkanDriver}) {
      SCOPED_TRACE(std::string(backend) + " with " + forced);
      const Result r =
          run({"render", scene, "--width", "16", "--height", "16", "--backend", backend}, forced);
      ASSERT_TRUE(r.exited);
      EXPECT_EQ(r.code, 2) << r.err;
      EXPECT_TRUE(one_line_message(r.err)) << r.err;
      EXPECT_EQ(r.err.rfind("specula: not available: backend '" + std::string(backend) + "'", 0),
                0u)
          << r.err;
      EXPECT_TRUE(r.out.empty()) << r.out;
    }
  if (!in_this_build("vulkan")) return;
  const Result named = run(
      {"render", scene, "--width", "8", "--height", "8", "--backend", "vulkan"}, kNoVulkanDevice);
  EXPECT_NE(named.err.find("no-such-device"), std::string::npos)
      << "the reason names the device asked for: " << named.err;
}

TEST(Cli, AutoWithoutARealGpuSaysInOneLineWhyTheCpuBackendWasChosen) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  for (const char* forced : {kNoVulkanDevice, kNoVulkanDriver}) {
    SCOPED_TRACE(forced);
    const Result r =
        run({"render", scene, "--width", "16", "--height", "16", "--mode", "cast"}, forced);
    ASSERT_TRUE(r.exited);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(one_line_message(r.err)) << r.err;
    EXPECT_NE(r.err.find("specula: note: --backend auto: no Vulkan GPU"), std::string::npos)
        << r.err;
    EXPECT_NE(r.err.find("using the CPU backend"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find(" on vulkan"), std::string::npos) << r.out;
  }
  // Here (lavapipe at most), the plain run says the same, naming the software device.
  const std::optional<std::string> why = specula::auto_cpu_reason();
  if (!why) GTEST_SKIP() << "a real GPU: auto picks vulkan";
  const Result plain = run({"render", scene, "--width", "16", "--height", "16", "--mode", "cast"});
  ASSERT_EQ(plain.code, 0) << plain.err;
  EXPECT_EQ(plain.err, "specula: note: --backend auto: " + *why + "\n");
  // A named backend asks no explanation.
  const Result named =
      run({"render", scene, "--width", "16", "--height", "16", "--backend", "native"});
  ASSERT_EQ(named.code, 0) << named.err;
  EXPECT_TRUE(named.err.empty()) << named.err;
}

TEST(Cli, TimeRangeRejectsBadValuesNamingTheOption) {
  for (const std::string value :
       {"2:1", "1", ":", "a:1", "0:1:2", "nan:1", "0:inf", "-1:2", "0:1e10", "0x1:2"}) {
    const Result r = run({"render",
                          (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string(),
                          "--width", "8", "--height", "8", "--backend",
                          "native", "--time", value});
    ASSERT_TRUE(r.exited);
    EXPECT_EQ(r.code, 1) << value << "\n" << r.err;
    EXPECT_NE(r.err.find("--time: expected T0:T1"), std::string::npos) << r.err;
    EXPECT_TRUE(one_line_message(r.err)) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
  }
}

TEST(Cli, TimeRangeSpacesTheFramesEvenlyAndRecordsTheTimes) {
  const fs::path stats =
      fs::temp_directory_path() / ("specula_cli_time_" + std::to_string(::getpid()) + ".json");
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/dynamic_three_classes.json").string();
  const Result r = run({"render", scene, "--width", "16", "--height", "16", "--backend",
                        "native", "--frames", "5", "--time", "0.5:2.5", "--stats",
                        stats.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(slurp(stats));
  fs::remove(stats);
  EXPECT_DOUBLE_EQ(j.at("settings").at("time0").get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(j.at("settings").at("time1").get<double>(), 2.5);
  for (int i = 0; i < 5; ++i)
    EXPECT_NEAR(j.at("frames").at(i).at("time").get<double>(), 0.5 + 0.5 * i, 1e-12) << i;
  EXPECT_NE(r.out.find("systems ms (median): animation "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" refit, "), std::string::npos) << r.out;
  // Without --time the frames step 1/60 s from 1/60, as before.
  const Result plain = run({"render", scene, "--width", "8", "--height", "8", "--backend",
                            "native", "--frames", "2", "--stats", stats.string()});
  ASSERT_EQ(plain.code, 0) << plain.err;
  const auto p = nlohmann::json::parse(slurp(stats));
  fs::remove(stats);
  EXPECT_NEAR(p.at("frames").at(1).at("time").get<double>(), 2.0 / 60.0, 1e-12);
}

TEST(Cli, AScenesAnimationRangeIsRenderedWhenTimeIsLeftOut) {
  // basic.aff says `a 0 2 5`: three frames without --time show scene times 0, 1 and 2.
  const fs::path stats =
      fs::temp_directory_path() / ("specula_cli_aff_time_" + std::to_string(::getpid()) + ".json");
  const std::string scene = (fs::path(SPECULA_TEST_DATA_DIR) / "aff/basic.aff").string();
  const Result r = run({"render", scene, "--width", "8", "--height", "8", "--backend", "native",
                        "--frames", "3", "--stats", stats.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(slurp(stats));
  fs::remove(stats);
  EXPECT_DOUBLE_EQ(j.at("settings").at("time0").get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(j.at("settings").at("time1").get<double>(), 2.0);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(j.at("frames").at(i).at("time").get<double>(), double(i), 1e-12) << i;
}

TEST(Cli, GpuOptionsRejectBadValuesNamingTheOption) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  for (const auto& [option, value] :
       std::vector<std::pair<std::string, std::string>>{{"--gpu-execution", "fast"},
                                                        {"--gpu-execution", ""},
                                                        {"--gpu-primary", "gbuffer"},
                                                        {"--gpu-primary", ""},
                                                        {"--gpu-frames", "yes"},
                                                        {"--grid-density", "0"},
                                                        {"--grid-density", "-2"},
                                                        {"--grid-density", "65"},
                                                        {"--grid-density", "abc"},
                                                        {"--grid-density", "nan"}}) {
    const Result r = run(
        {"render", scene, "--width", "8", "--height", "8", "--backend", "native", option, value});
    ASSERT_TRUE(r.exited);
    EXPECT_EQ(r.code, 1) << option << " " << value << "\n" << r.err;
    EXPECT_NE(r.err.find(option), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
  }
  // Valid values pass on every backend (CPU backends ignore them).
  const Result ok =
      run({"render", scene, "--width", "8", "--height", "8", "--backend", "native",
           "--gpu-execution", "single", "--gpu-frames", "off", "--grid-density", "0.5"});
  EXPECT_EQ(ok.code, 0) << ok.err;
  const Result raster = run({"render", scene, "--width", "8", "--height", "8", "--backend",
                             "native", "--gpu-primary", "raster"});
  EXPECT_EQ(raster.code, 0) << raster.err;
}

/// Renders a tiny cast frame on a Vulkan backend; skips while the traversal kernels are the
/// groundwork's stub (which says "not implemented yet"). Sanitized builds preload lavapipe so that
/// LeakSanitizer does not take its globals for leaks once the loader unloads it (tests/CMakeLists.txt).
Result render_on_vulkan(const std::vector<std::string>& extra, std::string prefix = "") {
#ifdef SPECULA_KEEP_VULKAN_DRIVER
  const std::string keep = "export LD_PRELOAD=" + quote(SPECULA_KEEP_VULKAN_DRIVER);
  prefix = prefix.empty() ? keep : keep + "; " + prefix;
#endif
  std::vector<std::string> args = {
      "render",   (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string(),
      "--width",  "8",
      "--height", "8",
      "--mode",   "cast"};
  args.insert(args.end(), extra.begin(), extra.end());
  return run(args, prefix);
}

TEST(Cli, DeviceLostWhileRenderingExitsThreeNamingTheBackend) {
  if (!specula::backend_info("vulkan").available) GTEST_SKIP() << "no Vulkan device here";
  const Result r = render_on_vulkan({"--backend", "vulkan", "--gpu-frames", "off"},
                                    "export SPECULA_VK_SIMULATE_DEVICE_LOSS=1");
  ASSERT_TRUE(r.exited) << "a lost device is no crash";
  if (r.err.find("not implemented yet") != std::string::npos)
    GTEST_SKIP() << "traversal kernels not in this build yet: " << r.err;
  EXPECT_EQ(r.code, 3) << r.err;
  EXPECT_TRUE(one_line_message(r.err)) << r.err;
  EXPECT_EQ(r.err.rfind("specula: backend 'vulkan' on ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("VK_ERROR_DEVICE_LOST"), std::string::npos) << r.err;
}

TEST(Cli, VulkanRunsWriteTheDeviceAndGpuCountersIntoTheStats) {
  if (!specula::backend_info("vulkan").available) GTEST_SKIP() << "no Vulkan device here";
  const fs::path stats =
      fs::temp_directory_path() / ("specula_cli_gpu_" + std::to_string(::getpid()) + ".json");
  const Result r = render_on_vulkan({"--backend", "vulkan-grid", "--gpu-execution", "single",
                                     "--grid-density", "2", "--stats", stats.string()});
  if (r.err.find("not implemented yet") != std::string::npos)
    GTEST_SKIP() << "traversal kernels not in this build yet: " << r.err;
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(slurp(stats));
  fs::remove(stats);
  const auto& gpu = j.at("settings").at("gpu");
  EXPECT_FALSE(gpu.at("device").get<std::string>().empty());
  EXPECT_EQ(gpu.at("execution"), "single kernel");
  EXPECT_EQ(gpu.at("grid_density"), 2.0);
  EXPECT_EQ(j.at("frames").at(0).at("gpu").at("cut"), 0) << "no ray cut off by the driver";
  EXPECT_NE(r.out.find("  device: "), std::string::npos) << r.out;
}

TEST(Cli, HybridRunsRecordTheirPrimaryVisibilityInTheStats) {
  if (!specula::backend_info("vulkan").available) GTEST_SKIP() << "no Vulkan device here";
  const fs::path stats =
      fs::temp_directory_path() / ("specula_cli_hybrid_" + std::to_string(::getpid()) + ".json");
  const Result r =
      render_on_vulkan({"--backend", "vulkan", "--gpu-primary", "raster", "--stats", stats.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(slurp(stats));
  fs::remove(stats);
  EXPECT_EQ(j.at("settings").at("gpu").at("primary"), "raster");
  EXPECT_EQ(j.at("frames").at(0).at("gpu").at("cut"), 0) << "no ray cut off by the driver";
}

TEST(Cli, InfoWithoutASceneListsBackendsAndVulkanDevices) {
  const Result r = run({"info", "--json"});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("auto"), specula::resolve_backend("auto"));
  std::size_t chosen = 0;
  for (const auto& d : j.at("vulkan_devices")) chosen += d.at("chosen").get<bool>() ? 1 : 0;
  EXPECT_EQ(chosen, specula::backend_info("vulkan").available ? 1u : 0u)
      << "exactly one device is chosen when the backend is available";
  for (const auto& b : j.at("backends")) {
    if (b.at("name") == "native") {
      EXPECT_TRUE(b.at("available").get<bool>());
    }
  }
  // With no device that fits, none is chosen and the reason is given.
  const Result none = run({"info", "--json"}, kNoVulkanDevice);
  ASSERT_EQ(none.code, 0) << none.err;
  const auto k = nlohmann::json::parse(none.out);
  for (const auto& d : k.at("vulkan_devices")) EXPECT_FALSE(d.at("chosen").get<bool>());
  if (in_this_build("vulkan")) {
    EXPECT_NE(k.at("vulkan_unavailable").get<std::string>().find("no-such-device"),
              std::string::npos);
  }
  EXPECT_NE(k.at("auto"), "vulkan");
  const Result text = run({"info"});
  ASSERT_EQ(text.code, 0) << text.err;
  EXPECT_NE(text.out.find("Vulkan devices:"), std::string::npos) << text.out;
}

TEST(Cli, PathAndShadowModesAccumulateFramesAndSayHowManySamples) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  const fs::path stats = fs::temp_directory_path() /
                         ("specula_cli_accumulate_" + std::to_string(::getpid()) + ".json");
  for (const char* mode : {"path", "shadow"}) {
    SCOPED_TRACE(mode);
    const Result r = run({"render", scene, "--mode", mode, "--width", "16", "--height", "16",
                          "--frames", "3", "--spp", "2", "--shadow-samples", "2", "--sampling",
                          "light", "--seed", "9", "--stats", stats.string()});
    ASSERT_TRUE(r.exited);
    if (r.code == 2) {
      EXPECT_NE(r.err.find("not available"), std::string::npos) << r.err;
      continue; // the integrator has not landed in this build
    }
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("samples per pixel: 6 in the image (2 per frame, accumulated, 1 "
                         "restart(s)), light sampling, seed 9"),
              std::string::npos)
        << r.out;
    const auto j = nlohmann::json::parse(slurp(stats));
    EXPECT_EQ(j.at("settings").at("spp"), 2);
    EXPECT_EQ(j.at("settings").at("sampling"), "light");
    EXPECT_EQ(j.at("settings").at("seed"), 9);
    EXPECT_EQ(j.at("settings").at("accumulate"), true);
    EXPECT_EQ(j.at("settings").at("denoise"), false);
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(j.at("frames").at(k).at("accumulated_samples"), 2 * (k + 1)) << k;
      EXPECT_EQ(j.at("frames").at(k).at("accumulation_restarted"), k == 0) << k;
    }
    const Result off = run({"render", scene, "--mode", mode, "--width", "16", "--height", "16",
                            "--frames", "3", "--spp", "2", "--shadow-samples", "2",
                            "--accumulate", "off"});
    ASSERT_EQ(off.code, 0) << off.err;
    EXPECT_NE(off.out.find("samples per pixel: 2 in the image (2 per frame, not accumulated"),
              std::string::npos)
        << off.out;
  }
  fs::remove(stats);
}

TEST(Cli, AutoIsTheDefaultBackendAndSaysWhichItPicked) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  const Result r = run({"render", scene, "--width", "16", "--height", "16", "--mode", "cast"});
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string picked = specula::resolve_backend("auto");
  EXPECT_NE(r.out.find("on " + picked + " (auto)"), std::string::npos) << r.out;
  for (const std::string& backend : cpu_backends()) {
    const Result named =
        run({"render", scene, "--width", "16", "--height", "16", "--backend", backend});
    ASSERT_EQ(named.code, 0) << named.err;
    EXPECT_NE(named.out.find("on " + backend + ","), std::string::npos) << named.out;
  }
}

TEST(Cli, RenderReportsTheFramesRaysPerSecondOfTracingTime) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  const Result r = run({"render", scene, "--width", "32", "--height", "32", "--frames", "2"});
  ASSERT_EQ(r.code, 0) << r.err;
  // One rate, of all the frame's rays over the tracing time; the per-kind counts beside it.
  EXPECT_NE(r.out.find("rays per frame: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("(primary 1024, shadow "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("Mrays/s of tracing time"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("primary rays:"), std::string::npos) << "the old per-kind rates are gone";
}

TEST(Cli, RenderOfABadSceneIsBadInputNotUnavailable) {
  const Result r = run({"render", "/no/such/scene.json"});
  EXPECT_EQ(r.code, 1) << r.err;
}

/// Whether a committed test file is bad input: tests/data/json/bad/*, tests/data/gltf/bad_*, the
/// inputs fuzzers once broke a reader with (tests/data/fuzz-regressions/READER/*), and every mesh
/// file except the good ones the mesh tests load.
bool is_bad_input(const fs::path& file) {
  static const std::set<std::string> kGoodMeshes = {
      "cube.obj",           "cube.off",        "cube_ascii.ply",        "cube_binary.off",
      "cube_binary.ply",    "cube_binary.stl", "cube_face_normals.obj", "nonmanifold_uv.obj",
      "normals.off",        "quad_uv.obj",     "texcoords.off",         "tri.stl",
      "with_degenerate.obj"};
  const std::string dir = file.parent_path().filename().string();
  const std::string name = file.filename().string();
  if (dir == "bad" || name.rfind("bad_", 0) == 0) return true;
  if (file.parent_path().parent_path().filename() == "fuzz-regressions") return true;
  if (dir == "mesh") return kGoodMeshes.count(name) == 0;
  return false;
}

/// Every committed scene and mesh test file through the program: bad input ends with exit code 1
/// and a message that names the file; good input loads (exit 0); nothing crashes.
TEST(Cli, EveryBadTestFileExitsOneNamingItAndEveryGoodOneLoads) {
  auto files = files_under(SPECULA_TEST_DATA_DIR, kSceneExtensions);
  files.push_back(fs::path(SPECULA_TEST_DATA_DIR) / "mesh/cube.xyz"); // unknown extension
  std::size_t bad = 0;
  for (const auto& file : files) {
    const Result r = run({"info", file.string()});
    ASSERT_TRUE(r.exited) << file << " killed the program";
    if (is_bad_input(file)) {
      ++bad;
      EXPECT_EQ(r.code, 1) << file << "\n" << r.out << r.err;
      EXPECT_NE(r.err.find(file.filename().string()), std::string::npos) << file << "\n" << r.err;
      EXPECT_EQ(r.err.rfind("specula: error: ", 0), 0u) << r.err;
    } else {
      EXPECT_EQ(r.code, 0) << file << "\n" << r.err;
    }
  }
  EXPECT_GE(bad, 90u) << "the bad-input corpus shrank";
}

/// Debian's assimp-testmodels: hundreds of real and deliberately broken files in the formats
/// Specula reads. Each either loads or is reported as bad input; none crashes.
TEST(Cli, NoAssimpTestModelCrashesTheProgram) {
  const fs::path root = "/usr/share/assimp/models";
  if (!fs::is_directory(root)) GTEST_SKIP() << "assimp-testmodels is not installed";
  const auto files = files_under(root, kSceneExtensions);
  std::size_t loaded = 0;
  for (const auto& file : files) {
    const Result r = run({"info", file.string()});
    ASSERT_TRUE(r.exited) << file << " killed the program";
    EXPECT_TRUE(r.code == 0 || r.code == 1) << file << " exit " << r.code << "\n" << r.err;
    if (r.code == 1) {
      EXPECT_NE(r.err.find(file.filename().string()), std::string::npos) << r.err;
    }
    loaded += r.code == 0 ? 1 : 0;
  }
  // Most of them are valid: a loader that rejects everything must not pass.
  EXPECT_GT(loaded, files.size() / 2) << loaded << " of " << files.size() << " loaded";
}

// --- Contract breaks of issue 13 ---------------------------------------------------------------

std::string cornell_box() {
  return (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
}

/// A fresh folder under the temporary directory, removed at the end of the test.
struct TempFolder {
  fs::path path;
  explicit TempFolder(const std::string& name)
      : path(fs::temp_directory_path() /
             ("specula_cli_" + name + "_" + std::to_string(::getpid()))) {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempFolder() { fs::remove_all(path); }
  [[nodiscard]] std::string file(const std::string& name) const { return (path / name).string(); }
};

/// The files in a folder, by name.
std::set<std::string> names_in(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir))
    names.insert(entry.path().filename().string());
  return names;
}

void expect_bad_input(const Result& r, const std::string& context) {
  ASSERT_TRUE(r.exited) << context;
  EXPECT_EQ(r.code, 1) << context << "\n" << r.out << r.err;
  EXPECT_EQ(r.err.rfind("specula: error: ", 0), 0u) << context << "\n" << r.err;
}

TEST(CliContract, WritingToAFullDeviceFailsNamingTheFile) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const TempFolder dir("full");
  // A device under a name with the image's extension: the write itself must fail and say so.
  for (const char* name : {"full.png", "full.exr"})
    fs::create_symlink("/dev/full", dir.path / name);
  fs::copy_file(cornell_box(), dir.path / "scene.json");
  // A named backend: no `auto` note precedes the error on stderr.
  for (const char* name : {"full.png", "full.exr"}) {
    const Result r = run({"render", cornell_box(), "--width", "16", "--height", "16", "--mode",
                          "cast", "--backend", "native", "--out", dir.file(name)});
    expect_bad_input(r, name);
    EXPECT_NE(r.err.find(name), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("image:"), std::string::npos) << "no path printed as written: " << r.out;
  }
  const std::string png = dir.file("a.png");
  ASSERT_EQ(run({"render", cornell_box(), "--width", "16", "--height", "16", "--out", png}).code,
            0);
  const Result r = run({"compare", png, png, "--heatmap", dir.file("full.png")});
  expect_bad_input(r, "compare --heatmap full.png");
  EXPECT_NE(r.err.find("full.png"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
}

TEST(CliContract, AFailedWriteLeavesTheOldImageAndNoTemporaryFile) {
  // A file size limit of 1 KiB or less (ulimit -f counts 512-byte blocks in dash, 1024 in bash)
  // makes the write of a 64x64 render fail part-way; SIGXFSZ ignored, it fails with EFBIG.
  const TempFolder dir("partial");
  for (const char* name : {"old.png", "old.exr"})
    std::ofstream(dir.file(name)) << "the previous image";
  for (const char* name : {"old.png", "old.exr"}) {
    const Result r = run({"render", cornell_box(), "--width", "64", "--height", "64", "--mode",
                          "cast", "--backend", "native", "--out", dir.file(name)},
                         "ulimit -f 2; trap '' XFSZ");
    expect_bad_input(r, name);
    EXPECT_NE(r.err.find(name), std::string::npos) << r.err;
    EXPECT_EQ(slurp(dir.file(name)), "the previous image") << name << " was overwritten";
    EXPECT_EQ(names_in(dir.path), (std::set<std::string>{"old.exr", "old.png"}))
        << "a temporary file was left behind";
  }
  // Without the limit, the same command replaces the file with a complete image.
  const Result r = run({"render", cornell_box(), "--width", "64", "--height", "64", "--mode",
                        "cast", "--out", dir.file("old.png")});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(slurp(dir.file("old.png")).substr(1, 3), "PNG");
  EXPECT_EQ(run({"compare", dir.file("old.png"), dir.file("old.png")}).code, 0);
  EXPECT_EQ(names_in(dir.path), (std::set<std::string>{"old.exr", "old.png"}));
}

TEST(CliContract, EmptyPathsAreErrorsNotNoFile) {
  const TempFolder dir("empty");
  const std::string png = dir.file("a.png");
  ASSERT_EQ(run({"render", cornell_box(), "--width", "8", "--height", "8", "--out", png}).code, 0);
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
           {"render", cornell_box(), "--width", "8", "--height", "8", "--out", ""},
           {"render", cornell_box(), "--width", "8", "--height", "8", "--stats", ""},
           {"compare", png, png, "--heatmap", ""},
           {"info", ""},
           {"compare", "", png}}) {
    const Result r = run(args);
    expect_bad_input(r, args[0] + " with an empty path");
    EXPECT_NE(r.err.find("empty"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
  }
}

TEST(CliContract, UnsupportedOutputExtensionsAreRefusedBeforeTheWork) {
  const TempFolder dir("ext");
  const std::string png = dir.file("a.png");
  ASSERT_EQ(run({"render", cornell_box(), "--width", "8", "--height", "8", "--out", png}).code, 0);
  // --out takes what the writer writes: .png and .exr. Refused before rendering (nothing on
  // stdout), and nothing written.
  for (const char* name : {"x.jpg", "x", "x.png.tmp"}) {
    const Result r =
        run({"render", cornell_box(), "--width", "8", "--height", "8", "--out", dir.file(name)});
    expect_bad_input(r, name);
    EXPECT_NE(r.err.find("(expected .png or .exr)"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir.file(name)));
  }
  // The heatmap is a PNG, so only .png (an .exr of it would have to be linear radiance).
  for (const char* name : {"x.jpg", "x.exr"}) {
    const Result r = run({"compare", png, png, "--heatmap", dir.file(name)});
    expect_bad_input(r, name);
    EXPECT_NE(r.err.find("(expected .png)"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir.file(name)));
  }
  // And a folder that does not exist is found before rendering too.
  const Result r = run({"render", cornell_box(), "--width", "8", "--height", "8", "--out",
                        dir.file("missing/x.png")});
  expect_bad_input(r, "missing folder");
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
}

TEST(CliContract, EveryParseErrorHasTheHousePrefix) {
  for (const std::vector<std::string>& args :
       std::vector<std::vector<std::string>>{{},
                                             {"frobnicate"},
                                             {"render"},
                                             {"info", cornell_box(), "--bogus"},
                                             {"render", cornell_box(), "--mode", "radiosity"},
                                             {"render", cornell_box(), "--width"},
                                             {"render", cornell_box(), "--frames", "0"},
                                             {"compare", "a.png"}}) {
    std::string joined;
    for (const auto& a : args) joined += a + " ";
    const Result r = run(args);
    expect_bad_input(r, joined);
    EXPECT_NE(r.err.find("Run with --help"), std::string::npos) << joined << "\n" << r.err;
  }
  EXPECT_EQ(run({"--help"}).code, 0);
  EXPECT_EQ(run({"render", "--help"}).code, 0);
}

TEST(CliContract, PathModeRefusesTheCentreFillsAndSaysWhy) {
  // Path mode's cubes average path samples: the fills that trace Whitted radiance from the
  // centre cannot fill them.
  for (const std::vector<std::string>& fill :
       {std::vector<std::string>{"--cache-prefill"},
        std::vector<std::string>{"--cache-fill-ahead", "1000"}}) {
    std::vector<std::string> args = {"render", cornell_box(), "--mode", "path", "--cache", "on"};
    args.insert(args.end(), fill.begin(), fill.end());
    const Result r = run(args);
    expect_bad_input(r, fill.front());
    EXPECT_NE(r.err.find(fill.front() + ": path mode's cubes average path samples"),
              std::string::npos)
        << r.err;
  }
}

TEST(CliContract, PathModesCacheSwitchesTakeOnOrOff) {
  for (const char* option : {"--cache-irradiance", "--cache-serve"}) {
    const Result r = run({"render", cornell_box(), option, "maybe"});
    expect_bad_input(r, option);
    EXPECT_NE(r.err.find(std::string(option) + ": expected on or off, got 'maybe'"),
              std::string::npos)
        << r.err;
  }
}

TEST(CliContract, ANonNumberIsNotCalledOutOfRange) {
  for (const auto& [option, value] :
       std::vector<std::pair<std::string, std::string>>{{"--width", "abc"},
                                                        {"--height", "0x10"},
                                                        {"--frames", "two"},
                                                        {"--threads", ""},
                                                        {"--cache-tau", "abc"},
                                                        {"--max-error-db", "40dB"},
                                                        {"--cache-fill", "many"},
                                                        {"--cache-fill-ahead", "lots"},
                                                        {"--cache-resolution", "big"}}) {
    const Result r = run({"render", cornell_box(), option, value});
    expect_bad_input(r, option + " " + value);
    EXPECT_NE(r.err.find(option + ": expected a number"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("not in range"), std::string::npos) << r.err;
  }
  // A number outside the range says what the range is.
  const Result r = run({"render", cornell_box(), "--width", "100000"});
  expect_bad_input(r, "--width 100000");
  EXPECT_NE(r.err.find("--width: expected a whole number in [1 - 16384], got 100000"),
            std::string::npos)
      << r.err;
  // An exponent is a number: 1e1 frames are 10.
  const Result ten = run({"render", cornell_box(), "--width", "4", "--height", "4", "--frames",
                          "1e1", "--mode", "cast"});
  EXPECT_EQ(ten.code, 0) << ten.err;
  EXPECT_NE(ten.out.find("10 frame(s)"), std::string::npos) << ten.out;
}

TEST(CliContract, EchoedInputIsEscapedAndCut) {
  // 100 KB with a line break and control bytes, as an option value and as a path: the message
  // is one line of bounded length, the bytes escaped.
  const std::string junk = "abc\ndef\x01" + std::string(100000, 'x');
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
           {"render", cornell_box(), "--mode", junk},
           {"render", cornell_box(), "--cache", junk},
           {"render", cornell_box(), "--width", junk},
           {"info", "/no/such/" + junk + ".json"},
           {"render", cornell_box(), "--out", "/tmp/" + junk + ".jpg"},
           {"compare", "/no/such/" + junk + ".png", "/no/such/b.png"}}) {
    const Result r = run(args);
    expect_bad_input(r, args[0] + " " + args[args.size() - 2]);
    EXPECT_LT(r.err.size(), 2000u) << r.err.substr(0, 300);
    const std::string first_line = r.err.substr(0, r.err.find('\n'));
    EXPECT_NE(first_line.find("abc\\ndef\\x01"), std::string::npos) << first_line.substr(0, 300);
    EXPECT_EQ(r.err.find('\x01'), std::string::npos);
  }
}

TEST(CliContract, MaxDepthHasOneLimitForInfoAndRender) {
  // The loader and the render job share kMaxTraceDepth (64): a depth the file may state is one
  // the renderer accepts, and one beyond it fails in both commands naming the file and field.
  const TempFolder dir("depth");
  std::string text = slurp(cornell_box());
  const auto settings = nlohmann::json::parse(text).at("settings");
  ASSERT_TRUE(settings.contains("max_depth"));
  for (const int depth : {33, 64, 65}) {
    auto scene = nlohmann::json::parse(text);
    scene["settings"]["max_depth"] = depth;
    const std::string name = "depth" + std::to_string(depth) + ".json";
    std::ofstream(dir.file(name)) << scene.dump();
    const Result info = run({"info", "--json", dir.file(name)});
    const Result render = run({"render", dir.file(name), "--width", "16", "--height", "16"});
    if (depth <= 64) {
      ASSERT_EQ(info.code, 0) << info.err;
      EXPECT_EQ(nlohmann::json::parse(info.out)["settings"]["max_depth"], depth);
      EXPECT_EQ(render.code, 0) << render.err;
    } else {
      for (const Result* r : {&info, &render}) {
        expect_bad_input(*r, name);
        EXPECT_NE(r->err.find(name + ": settings.max_depth: "), std::string::npos) << r->err;
      }
      EXPECT_EQ(info.err, render.err) << "the same answer from both commands";
    }
  }
}

/// A PNG of the given size that is only a signature and an IHDR chunk: enough for the size
/// checks, which must come before anything is decoded.
void write_png_header(const std::string& path, std::uint32_t width, std::uint32_t height) {
  std::string bytes = "\x89PNG\r\n\x1a\n";
  bytes += std::string("\0\0\0\x0dIHDR", 8);
  for (const std::uint32_t v : {width, height})
    for (int shift = 24; shift >= 0; shift -= 8) bytes += char((v >> shift) & 0xff);
  bytes += std::string("\x08\x02\0\0\0", 5); // 8-bit RGB
  bytes += std::string("\0\0\0\0", 4);       // CRC, never reached
  std::ofstream(path, std::ios::binary) << bytes;
}

TEST(CliContract, CompareRefusesImagesBeyondTheMemoryBudgetFromTheirHeaders) {
  const TempFolder dir("budget");
  write_png_header(dir.file("big_a.png"), 16384, 16384);
  write_png_header(dir.file("big_b.png"), 16384, 16384);
  // Two 16384² images need several GiB however they are compared: with a budget of 4 GiB the
  // refusal comes from the headers (the files have no pixel data: decoding would have said so).
  const Result r =
      run({"compare", dir.file("big_a.png"), dir.file("big_b.png"), "--memory-limit", "4G"});
  expect_bad_input(r, "compare 16384²");
  EXPECT_NE(r.err.find("big_a.png"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("16384x16384"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("more than the memory budget of 4.00 GiB (--memory-limit 4G)"),
            std::string::npos)
      << r.err;
  // Sizes that differ are found in the headers too, before decoding.
  write_png_header(dir.file("other.png"), 16384, 8192);
  const Result sizes = run({"compare", dir.file("big_a.png"), dir.file("other.png")});
  expect_bad_input(sizes, "sizes differ");
  EXPECT_NE(sizes.err.find("image size 16384x8192 differs"), std::string::npos) << sizes.err;
  // Real images within the budget compare; the same under a budget too small do not.
  const std::string png = dir.file("a.png");
  ASSERT_EQ(run({"render", cornell_box(), "--width", "64", "--height", "64", "--out", png}).code,
            0);
  EXPECT_EQ(run({"compare", png, png, "--memory-limit", "100M"}).code, 0);
  const Result tight = run({"compare", png, png, "--memory-limit", "1M"});
  expect_bad_input(tight, "1M");
  EXPECT_NE(tight.err.find("memory budget"), std::string::npos) << tight.err;
  expect_bad_input(run({"compare", png, png, "--memory-limit", "lots"}), "--memory-limit lots");
}

TEST(CliContract, RenderRefusesAFramebufferBeyondTheMemoryBudgetBeforeAllocating) {
  // 16384² needs 3 GiB for the framebuffer alone (more with the PNG): refused at once, naming
  // the scene, under a 1 GiB budget.
  const Result r = run({"render", cornell_box(), "--width", "16384", "--height", "16384",
                        "--memory-limit", "1G", "--out", "/tmp/never.png"});
  expect_bad_input(r, "render 16384²");
  EXPECT_NE(r.err.find("cornell_box.json: rendering 1 frame(s) of 16384x16384 needs about"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("memory budget of 1.00 GiB"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty());
  EXPECT_EQ(
      run({"render", cornell_box(), "--width", "16", "--height", "16", "--memory-limit", "1G"})
          .code,
      0);
}

TEST(CliContract, InfoJsonSurvivesAPathThatIsNotUtf8) {
  const TempFolder dir("utf8");
  const std::string odd = dir.file("scene\xff.json");
  fs::copy_file(cornell_box(), odd);
  const Result r = run({"info", "--json", odd});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(nlohmann::json::parse(r.out, nullptr, false).is_discarded()) << r.out;
  const Result text = run({"info", odd});
  ASSERT_EQ(text.code, 0) << text.err;
  EXPECT_NE(text.out.find("scene\\xff.json"), std::string::npos) << text.out;
}

} // namespace
