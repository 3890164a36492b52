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
#include <set>
#include <sstream>
#include <string>
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

Result run(const std::vector<std::string>& args) {
  static int counter = 0;
  const fs::path dir = fs::temp_directory_path();
  const std::string tag = std::to_string(::getpid()) + "_" + std::to_string(counter++);
  const fs::path out = dir / ("specula_cli_out_" + tag);
  const fs::path err = dir / ("specula_cli_err_" + tag);
  std::string cmd = quote(SPECULA_EXE);
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
    EXPECT_GE(j.at("lights").get<long>(), 1) << scene;
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

TEST(Cli, BackendsAndModesNotBuiltYetExitTwo) {
  const std::string scene =
      (fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json").string();
  std::vector<std::vector<std::string>> unavailable = {{"--backend", "vulkan"},
                                                             {"--mode", "path"},
                                                             {"--mode", "shadow"}};
  if (!specula::backend_info("embree").available) unavailable.push_back({"--backend", "embree"});
  for (const auto& extra : unavailable) {
    std::vector<std::string> args = {"render", scene, "--width", "16", "--height", "16"};
    args.insert(args.end(), extra.begin(), extra.end());
    const Result r = run(args);
    ASSERT_TRUE(r.exited);
    EXPECT_EQ(r.code, 2) << extra[0] << " " << extra[1] << "\n" << r.err;
    EXPECT_NE(r.err.find("specula: not available: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(extra[1]), std::string::npos)
        << "the message names what is missing: " << r.err;
  }
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

/// Whether a committed test file is bad input: tests/data/json/bad/*, tests/data/gltf/bad_*, and
/// every mesh file except the good ones the mesh tests load.
bool is_bad_input(const fs::path& file) {
  static const std::set<std::string> kGoodMeshes = {
      "cube.obj",           "cube.off",        "cube_ascii.ply",        "cube_binary.off",
      "cube_binary.ply",    "cube_binary.stl", "cube_face_normals.obj", "nonmanifold_uv.obj",
      "normals.off",        "quad_uv.obj",     "texcoords.off",         "tri.stl",
      "with_degenerate.obj"};
  const std::string dir = file.parent_path().filename().string();
  const std::string name = file.filename().string();
  if (dir == "bad" || name.rfind("bad_", 0) == 0) return true;
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

} // namespace
