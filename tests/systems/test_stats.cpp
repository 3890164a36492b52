#include "specula/core/error.h"
#include "specula/trace/stats.h"

#include <nlohmann/json.hpp>
#include <gtest/gtest.h>

namespace specula {
namespace {

RunStats sample_stats() {
  RunStats s;
  s.settings = {"samples/scenes/cornell_box.json", "embree", "whitted", 512, 400, 3, 2, 5, 64};
  for (int i = 0; i < 3; ++i) {
    FrameStats f;
    f.ms = 10.0 + i;
    f.trace_ms = 8.0 + i;
    f.rays[RayKind::Primary] = 512 * 400;
    f.rays[RayKind::Shadow] = 1000u + unsigned(i);
    f.rays[RayKind::Reflection] = 77;
    f.rays[RayKind::Refraction] = 5;
    f.cache = {100, 40};
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
  EXPECT_EQ(j.at("settings").at("cache"), 64);
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
