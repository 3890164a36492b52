#include "specula/core/error.h"
#include "specula/trace/stats.h"

#include <nlohmann/json.hpp>
#include <gtest/gtest.h>

namespace specula {
namespace {

RunStats sample_stats() {
  RunStats s;
  s.settings = {"samples/scenes/cornell_box.json", "embree", "whitted", 512, 400, 3, 2, 5, 64};
  s.settings.cache_policy = "auto";
  s.settings.cache_lookup = "tau";
  s.settings.cache_tau_deg = 0.25f;
  s.settings.cache_fill_budget = 1000;
  s.settings.max_error_db = 35.0;
  s.settings.spp = 4;
  s.settings.shadow_samples = 16;
  s.settings.sampling = "light";
  s.settings.seed = 1234;
  s.settings.accumulate = false;
  s.settings.denoise = true;
  s.settings.denoise_iterations = 3;
  s.settings.denoise_sigma_color = 0.25f;
  s.settings.time0 = 0.5;
  s.settings.time1 = 2.25;
  for (int i = 0; i < 3; ++i) {
    FrameStats f;
    f.ms = 10.0 + i;
    f.trace_ms = 8.0 + i;
    f.rays[RayKind::Primary] = 512 * 400;
    f.rays[RayKind::Shadow] = 1000u + unsigned(i);
    f.rays[RayKind::Reflection] = 77;
    f.rays[RayKind::Refraction] = 5;
    f.cache.lookups = 100;
    f.cache.hits = 40;
    f.cache.rejected = 7;
    f.cache.written = 12u + unsigned(i);
    f.cache.texels = 6 * 64 * 64;
    f.cache.valid = 300;
    f.cache.memory_bytes = 6 * 64 * 64 * 16;
    CubeReport cube;
    cube.entity = 3;
    cube.resolution = 64;
    cube.mode = "tau";
    cube.reason = "estimated 41.5 dB, within the 40.0 dB bound: tau mode kept";
    cube.lookups = 100;
    cube.hits = 40;
    cube.valid = 300;
    cube.estimated_psnr_db = 41.5;
    cube.saved_ms = 0.25;
    f.cache.cubes.push_back(cube);
    f.accumulated_samples = 4u * unsigned(i + 1);
    f.accumulation_restarted = i == 0;
    f.denoise_ms = 0.5 + i;
    f.time = 0.5 + 0.875 * i;
    f.accel.triangles_rebuilt = i == 0 ? 5000u : 0u;
    f.accel.triangles_refit = 320u + unsigned(i);
    f.accel.triangles_untouched = 4680u - unsigned(i);
    f.systems = {0.01 + i, 0.02, 0.5, 1.25 + i, 0.125, 8.0 + i};
    s.frames.push_back(f);
  }
  return s;
}

TEST(Stats, RoundTripsThroughJson) {
  const RunStats s = sample_stats();
  EXPECT_EQ(stats_from_json(stats_to_json(s), "stats.json"), s);
}

TEST(Stats, UsesThePublishedFieldNames) {
  // Other tools read these names (docs/stats-format.md): they must not drift.
  const auto j = nlohmann::json::parse(stats_to_json(sample_stats()));
  const auto& f = j.at("frames").at(0);
  for (const char* k : {"primary", "shadow", "reflection", "refraction"}) EXPECT_TRUE(f.at("rays").contains(k)) << k;
  EXPECT_TRUE(f.contains("ms"));
  EXPECT_TRUE(f.contains("trace_ms"));
  EXPECT_TRUE(f.at("cache").contains("lookups"));
  EXPECT_TRUE(f.at("cache").contains("hits"));
  EXPECT_EQ(j.at("settings").at("cache").at("resolution"), 64);
  EXPECT_EQ(j.at("settings").at("cache").at("policy"), "auto");
  EXPECT_EQ(f.at("cache").at("cubes").at(0).at("mode"), "tau");
  EXPECT_EQ(j.at("settings").at("time0"), 0.5);
  EXPECT_EQ(f.at("time"), 0.5);
  for (const char* k : {"triangles_rebuilt", "triangles_refit", "triangles_untouched"})
    EXPECT_TRUE(f.at("accel").contains(k)) << k;
  for (const char* k :
       {"animation", "transform", "scene_layer", "acceleration", "cache_invalidation", "render"})
    EXPECT_TRUE(f.at("systems_ms").contains(k)) << k;
}

TEST(Stats, ReadsFilesFromBeforeTheCacheFields) {
  // A file as the first releases wrote it: "cache" a bare resolution, the frame's cache counts
  // only lookups and hits.
  auto j = nlohmann::json::parse(stats_to_json(sample_stats()));
  j["settings"]["cache"] = 128;
  for (auto& f : j["frames"]) f["cache"] = {{"lookups", 5}, {"hits", 2}};
  const RunStats s = stats_from_json(j.dump(), "old.json");
  EXPECT_EQ(s.settings.cache_resolution, 128u);
  EXPECT_EQ(s.settings.cache_policy, "auto");
  EXPECT_EQ(s.frames[0].cache.lookups, 5u);
  EXPECT_TRUE(s.frames[0].cache.cubes.empty());
}

TEST(Stats, WritesTheSamplingSettingsAndEachFramesAccumulation) {
  const auto j = nlohmann::json::parse(stats_to_json(sample_stats()));
  const auto& settings = j.at("settings");
  EXPECT_EQ(settings.at("spp"), 4);
  EXPECT_EQ(settings.at("shadow_samples"), 16);
  EXPECT_EQ(settings.at("sampling"), "light");
  EXPECT_EQ(settings.at("seed"), 1234);
  EXPECT_EQ(settings.at("accumulate"), false);
  EXPECT_EQ(settings.at("denoise").at("iterations"), 3);
  EXPECT_EQ(j.at("frames").at(1).at("accumulated_samples"), 8);
  EXPECT_EQ(j.at("frames").at(0).at("accumulation_restarted"), true);
  EXPECT_EQ(j.at("frames").at(1).at("accumulation_restarted"), false);
  EXPECT_DOUBLE_EQ(j.at("frames").at(2).at("denoise_ms").get<double>(), 2.5);
  EXPECT_EQ(j.at("summary").at("accumulated_samples"), 12);
  // Without the denoiser the field is false, not an object of unused settings.
  RunStats plain = sample_stats();
  plain.settings.denoise = false;
  EXPECT_EQ(nlohmann::json::parse(stats_to_json(plain)).at("settings").at("denoise"), false);
}

TEST(Stats, ReadsFilesFromBeforeTheStochasticModes) {
  auto j = nlohmann::json::parse(stats_to_json(sample_stats()));
  for (const char* k : {"spp", "shadow_samples", "sampling", "seed", "accumulate", "denoise"})
    j["settings"].erase(k);
  for (auto& f : j["frames"])
    for (const char* k : {"accumulated_samples", "accumulation_restarted", "denoise_ms"})
      f.erase(k);
  const RunStats s = stats_from_json(j.dump(), "old.json");
  EXPECT_EQ(s.settings.spp, 1u);
  EXPECT_EQ(s.settings.shadow_samples, 1u);
  EXPECT_EQ(s.settings.sampling, "mis");
  EXPECT_EQ(s.settings.seed, 0u);
  EXPECT_TRUE(s.settings.accumulate);
  EXPECT_FALSE(s.settings.denoise);
  EXPECT_EQ(s.frames[1].accumulated_samples, 0u);
  EXPECT_FALSE(s.frames[0].accumulation_restarted);
  EXPECT_EQ(s.frames[0].denoise_ms, 0.0);
  j["settings"]["denoise"] = "yes";
  EXPECT_THROW((void)stats_from_json(j.dump(), "bad.json"), Error);
}

TEST(Stats, ReadsFilesFromBeforeTheAnimationFields) {
  auto j = nlohmann::json::parse(stats_to_json(sample_stats()));
  for (const char* k : {"time0", "time1"}) j["settings"].erase(k);
  for (auto& f : j["frames"]) {
    f.erase("time");
    f.erase("systems_ms");
    for (const char* k : {"triangles_rebuilt", "triangles_refit", "triangles_untouched"})
      f["accel"].erase(k);
  }
  const RunStats s = stats_from_json(j.dump(), "old.json");
  EXPECT_EQ(s.settings.time1, 0.0);
  EXPECT_EQ(s.frames[1].time, 0.0);
  EXPECT_EQ(s.frames[1].systems, SystemTimes{});
  EXPECT_EQ(s.frames[0].accel.triangles_rebuilt, 0u);
  j["frames"][0]["systems_ms"] = {{"animation", 1.0}};
  EXPECT_THROW((void)stats_from_json(j.dump(), "bad.json"), Error) << "a partial systems_ms";
}

TEST(Stats, WritesTheDeviceAndGpuCountersOnlyForDeviceRuns) {
  RunStats s = sample_stats();
  const auto cpu = nlohmann::json::parse(stats_to_json(s));
  EXPECT_FALSE(cpu.at("settings").contains("gpu")) << "a CPU run names no device";
  EXPECT_FALSE(cpu.at("frames").at(0).contains("gpu"));
  s.settings.backend = "vulkan-grid";
  s.settings.gpu_device = "llvmpipe (LLVM 15.0.6, 256 bits)";
  s.settings.gpu_device_type = "CPU (software)";
  s.settings.gpu_execution = "single kernel";
  s.settings.gpu_device_frames = false;
  s.settings.grid_density = 2.0f;
  s.settings.gpu_primary = "raster";
  s.frames[0].gpu = {true, 4096, 12, 0, 3, 1.5};
  s.frames[0].gpu.submits = 4;
  const auto j = nlohmann::json::parse(stats_to_json(s));
  EXPECT_EQ(j.at("settings").at("gpu").at("primary"), "raster");
  EXPECT_EQ(j.at("settings").at("gpu").at("device_type"), "CPU (software)");
  EXPECT_EQ(j.at("settings").at("gpu").at("grid_density"), 2.0);
  EXPECT_EQ(j.at("frames").at(0).at("gpu").at("rays"), 4096);
  EXPECT_EQ(j.at("frames").at(0).at("gpu").at("cut"), 0);
  EXPECT_EQ(j.at("frames").at(0).at("gpu").at("submits"), 4);
  EXPECT_EQ(stats_from_json(stats_to_json(s), "gpu.json"), s);
  // Files from before hybrid mode have no "primary": they traced their primary rays.
  auto old = j;
  old["settings"]["gpu"].erase("primary");
  EXPECT_EQ(stats_from_json(old.dump(), "old.json").settings.gpu_primary, "trace");
  // Nor, from before 2026-11-29, a frame's submits.
  old["frames"][0]["gpu"].erase("submits");
  EXPECT_EQ(stats_from_json(old.dump(), "old.json").frames[0].gpu.submits, 0u);
}

TEST(Stats, WritesEachDeviceStagesTimeOnlyWhereItWasMeasured) {
  RunStats s = sample_stats();
  s.settings.backend = "vulkan";
  s.frames[0].gpu = {true, 4096, 0, 0, 9, 3.0};
  s.frames[1].gpu = {true, 4096, 0, 0, 9, 3.0};
  s.frames[1].gpu.stage_ms = {0.25, 0.0, 1.0, 0.75, 0.5, 0.5};
  const auto j = nlohmann::json::parse(stats_to_json(s));
  EXPECT_FALSE(j.at("frames").at(0).at("gpu").contains("stages_ms"))
      << "a frame without stage times (path, single kernel) writes none";
  const auto& stages = j.at("frames").at(1).at("gpu").at("stages_ms");
  for (int k = 0; k < kGpuStageCount; ++k)
    EXPECT_EQ(stages.at(gpu_stage_name(GpuStage(k))).get<double>(),
              s.frames[1].gpu.stage_ms[std::size_t(k)])
        << gpu_stage_name(GpuStage(k));
  EXPECT_EQ(stats_from_json(j.dump(), "gpu.json"), s);
  // A stage missing from the object is named.
  auto bad = j;
  bad["frames"][1]["gpu"]["stages_ms"].erase("fold");
  try {
    (void)stats_from_json(bad.dump(), "bad.json");
    FAIL() << "a partial stages_ms read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("frames[1].gpu.stages_ms.fold"), std::string::npos)
        << e.what();
  }
}

TEST(Stats, DerivedRatesFollowFromCountsAndTime) {
  const RunStats s = sample_stats();
  const auto j = nlohmann::json::parse(stats_to_json(s));
  const auto& f = j.at("frames").at(1);
  const double expected = double(s.frames[1].rays.total()) / (s.frames[1].trace_ms * 1e3);
  EXPECT_DOUBLE_EQ(f.at("mrays_per_s").at("total").get<double>(), expected);
  EXPECT_DOUBLE_EQ(j.at("summary").at("median_ms").get<double>(), 11.0);
  EXPECT_DOUBLE_EQ(j.at("summary").at("cache_hit_rate").get<double>(), 0.4);
}

TEST(Stats, MalformedStatsFileNamesTheField) {
  try {
    (void)stats_from_json(R"({"settings": {"scene": 3}, "frames": []})", "bad.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("settings.scene"), std::string::npos);
  }
  EXPECT_THROW((void)stats_from_json("{", "bad.json"), Error);
}

TEST(Stats, MedianIsTheMiddleValueOrTheMeanOfTheMiddleTwo) {
  EXPECT_EQ(median({}), 0.0);
  EXPECT_EQ(median({5.0}), 5.0);
  EXPECT_EQ(median({3.0, 1.0, 2.0}), 2.0);
  EXPECT_EQ(median({4.0, 1.0, 3.0, 2.0}), 2.5); // what the stats file and `specula render` show
}

} // namespace
} // namespace specula
