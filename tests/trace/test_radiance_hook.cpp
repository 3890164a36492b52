// The leaving-radiance hook: what a ray leaving an object brings back exists as its own value, and
// the values add up to the image. On the mirror-spheres scene of the ray-caching paper, where the
// front sphere reflects reflective hidden spheres (a sphere seen in a sphere).

#include "specula/render/render_job.h"
#include "specula/scene/components/name.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <set>
#include <vector>

namespace specula {
namespace {

/// Keeps every leaving ray, from every tile.
class Recorder final : public RadianceHook {
public:
  explicit Recorder(bool wants = true) : wants_(wants) {}
  [[nodiscard]] bool wants_leaving() const override { return wants_; }
  void leaving(std::span<const LeavingRadiance> rays) override {
    const std::lock_guard lock(mutex_);
    rays_.insert(rays_.end(), rays.begin(), rays.end());
  }
  std::vector<LeavingRadiance> rays_;

private:
  bool wants_;
  std::mutex mutex_;
};

struct Rendered {
  Framebuffer image{1, 1};
  std::vector<LeavingRadiance> rays;
  Scene scene;
};

Rendered render(std::uint32_t max_depth, bool record, std::uint32_t tile = 16,
                std::uint32_t threads = 2, TraceMode mode = TraceMode::Whitted,
                bool wants = true) {
  Rendered run;
  run.scene = load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) /
                         "samples/scenes/mirror_spheres_8.json");
  RenderJob job;
  job.settings.mode = mode;
  job.settings.max_depth = max_depth;
  job.settings.background = run.scene.settings.background;
  job.settings.tile_size = tile;
  job.settings.threads = threads;
  job.image = Framebuffer(96, 96);
  auto recorder = std::make_shared<Recorder>(wants);
  if (record) job.hook = recorder;
  prepare_rendering(run.scene.registry, std::move(job));
  Schedule schedule;
  schedule.tick(run.scene.registry, 0.0);
  run.image = run.scene.registry.resource<RenderJob>().image;
  run.rays = std::move(recorder->rays_);
  return run;
}

/// Per pixel, the sum over the given depth's leaving rays of `weight_of(ray) × radiance`.
template <typename Weight>
std::vector<vec3> per_pixel(const std::vector<LeavingRadiance>& rays, std::size_t pixels,
                            std::uint32_t depth, Weight weight_of) {
  std::vector<vec3> sum(pixels, vec3(0.0f));
  for (const LeavingRadiance& r : rays)
    if (r.depth == depth) sum[r.pixel] += weight_of(r) * r.radiance;
  return sum;
}

bool near(const vec3& a, const vec3& b) {
  const vec3 d = glm::abs(a - b);
  const vec3 tolerance = 1e-5f * glm::max(glm::abs(a), glm::abs(b)) + vec3(1e-6f);
  return glm::all(glm::lessThanEqual(d, tolerance));
}

TEST(RadianceHook, LeavingRaysAddUpToTheReflectedPartOfEveryPixel) {
  const Rendered full = render(5, true);
  const Rendered local = render(0, false); // primary hits shaded locally, nothing leaves them
  ASSERT_FALSE(full.rays.empty());
  const std::vector<vec3> reflected = per_pixel(full.rays, full.image.pixel_count(), 1,
                                                [](const LeavingRadiance& r) { return r.weight; });
  int mismatched = 0, reflecting = 0;
  for (std::size_t p = 0; p < full.image.pixel_count(); ++p) {
    if (glm::length(reflected[p]) > 0.0f) ++reflecting;
    if (!near(local.image.pixels()[p] + reflected[p], full.image.pixels()[p])) ++mismatched;
  }
  EXPECT_EQ(mismatched, 0);
  EXPECT_GT(reflecting, 500) << "the front sphere covers a good part of the frame";
  // Every leaving ray names the entity it leaves, and its kind.
  for (const LeavingRadiance& r : full.rays) {
    ASSERT_TRUE(full.scene.registry.valid(r.from));
    EXPECT_TRUE(r.kind == RayKind::Reflection || r.kind == RayKind::Refraction);
    EXPECT_NEAR(glm::length(r.direction), 1.0f, 1e-5f);
  }
}

TEST(RadianceHook, AHookThatWantsNoLeavingRaysGetsNoneAndTheImageIsTheSame) {
  // A hook with nothing to store (every ray-cache cube off) says so, and neither integrator
  // builds or delivers leaving rays for it.
  for (const TraceMode mode : {TraceMode::Whitted, TraceMode::Path}) {
    const Rendered told = render(5, true, 16, 2, mode, false);
    const Rendered plain = render(5, false, 16, 2, mode);
    EXPECT_TRUE(told.rays.empty()) << trace_mode_name(mode);
    EXPECT_EQ(std::memcmp(told.image.pixels().data(), plain.image.pixels().data(),
                          plain.image.pixels().size_bytes()),
              0)
        << trace_mode_name(mode);
  }
}

TEST(RadianceHook, NestedLeavingRaysAreReportedToBothOwnersAndFoldIntoTheOuterOne) {
  const Rendered full = render(5, true);
  const Rendered one_bounce = render(1, true); // depth-1 rays bring back their local shading only
  const std::size_t n = full.image.pixel_count();
  // What the depth-1 rays bring back beyond their local shading is exactly what their depth-2
  // children bring back, weighted by their share of the pixel.
  const std::vector<vec3> outer_full =
      per_pixel(full.rays, n, 1, [](const LeavingRadiance& r) { return r.weight; });
  const std::vector<vec3> outer_local =
      per_pixel(one_bounce.rays, n, 1, [](const LeavingRadiance& r) { return r.weight; });
  const std::vector<vec3> inner =
      per_pixel(full.rays, n, 2, [](const LeavingRadiance& r) { return r.throughput; });
  int mismatched = 0;
  for (std::size_t p = 0; p < n; ++p) {
    const vec3 lhs = outer_full[p] - outer_local[p];
    const vec3 d = glm::abs(lhs - inner[p]);
    if (glm::any(
            glm::greaterThan(d, 2e-5f * glm::max(glm::abs(lhs), glm::abs(inner[p])) + vec3(2e-6f))))
      ++mismatched;
  }
  EXPECT_EQ(mismatched, 0);

  // Pixels where the ray leaving the front sphere lands on a hidden sphere, whose own leaving ray
  // is delivered to it: both owners hear about their ray.
  const ecs::Registry& reg = full.scene.registry;
  std::map<std::uint32_t, std::set<std::string>> owners_by_pixel_depth1, owners_by_pixel_depth2;
  for (const LeavingRadiance& r : full.rays) {
    const Name* name = reg.try_get<Name>(r.from);
    ASSERT_NE(name, nullptr);
    (r.depth == 1 ? owners_by_pixel_depth1 : owners_by_pixel_depth2)[r.pixel].insert(name->value);
  }
  int nested = 0;
  for (const auto& [pixel, inner_owners] : owners_by_pixel_depth2) {
    const auto outer = owners_by_pixel_depth1.find(pixel);
    if (outer == owners_by_pixel_depth1.end() || !outer->second.contains("mirror sphere")) continue;
    for (const std::string& owner : inner_owners)
      nested += owner.starts_with("hidden sphere") ? 1 : 0;
  }
  EXPECT_GT(nested, 20) << "hidden spheres must be seen in the front sphere";
}

TEST(RadianceHook, DeliveriesAreTheSameWhateverTheTilesAndThreads) {
  const Rendered a = render(5, true, 16, 2);
  const Rendered b = render(5, true, 7, 1);
  ASSERT_EQ(a.rays.size(), b.rays.size());
  // Tiles arrive in any order; within a pixel the rays come in a fixed order.
  const auto key = [](const LeavingRadiance& r) {
    return std::make_tuple(r.pixel, r.depth, r.kind);
  };
  std::multimap<std::tuple<std::uint32_t, std::uint32_t, RayKind>, vec3> in_a, in_b;
  for (const LeavingRadiance& r : a.rays) in_a.emplace(key(r), r.radiance);
  for (const LeavingRadiance& r : b.rays) in_b.emplace(key(r), r.radiance);
  EXPECT_TRUE(in_a == in_b);
  EXPECT_TRUE(a.image == b.image);
}

TEST(RadianceHook, InPathModeALeavingRayBringsBackTheRestOfItsPath) {
  // One sample per pixel: a pixel is its primary vertex's own part (emission and next-event
  // estimates, which the same sample gives with nothing beyond it: max_depth 0) plus, when its
  // path left the front sphere by a specular bounce, throughput × what that ray brought back
  // (the scene has no emitters, so that is all of it: the emission at the ray's first hit, which
  // a path-mode leaving ray leaves out, is zero; tests/cache checks a scene with one).
  const Rendered full = render(5, true, 16, 2, TraceMode::Path);
  const Rendered local = render(0, false, 16, 2, TraceMode::Path);
  const std::size_t n = full.image.pixel_count();
  std::vector<int> leaving(n, 0);
  std::vector<vec3> outer(n, vec3(0.0f)), inner(n, vec3(0.0f));
  for (const LeavingRadiance& r : full.rays) {
    ASSERT_TRUE(r.exits);
    ASSERT_EQ(r.answer, CacheAnswer::Trace) << "nothing is cached: every ray is traced";
    ASSERT_TRUE(std::isfinite(r.radiance.x + r.radiance.y + r.radiance.z));
    if (r.depth == 1) {
      ++leaving[r.pixel];
      outer[r.pixel] = r.throughput * r.radiance;
    } else if (r.depth == 2) {
      inner[r.pixel] = r.throughput * r.radiance;
    }
  }
  int checked = 0, mismatched = 0, nested = 0, nested_larger = 0;
  for (std::size_t p = 0; p < n; ++p) {
    ASSERT_LE(leaving[p], 1) << "one sample, one path: at most one ray leaves its primary hit";
    if (leaving[p] == 0) continue;
    ++checked;
    const vec3 sum = local.image.pixels()[p] + outer[p];
    const vec3 got = full.image.pixels()[p];
    if (glm::any(glm::greaterThan(glm::abs(sum - got), 1e-5f * glm::abs(got) + vec3(1e-6f))))
      ++mismatched;
    // A nested leaving ray's contribution is part of the outer one's.
    if (glm::length(inner[p]) > 0.0f) {
      ++nested;
      if (glm::any(glm::lessThan(outer[p], inner[p] * (1.0f - 1e-5f)))) ++nested_larger;
    }
  }
  EXPECT_GT(checked, 500);
  EXPECT_EQ(mismatched, 0);
  // (A hidden sphere's path takes its specular lobe about half the time.)
  EXPECT_GT(nested, 5) << "hidden spheres must be seen in the front sphere";
  EXPECT_EQ(nested_larger, 0);
}

} // namespace
} // namespace specula
