#include "specula/image/denoise.h"

#include "specula/core/error.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <thread>

namespace specula {
namespace {

/// Most levels: at 12 the footprint (4·2^12 + 1 pixels) already spans the largest framebuffer.
constexpr std::uint32_t kMaxIterations = 12;

/// Albedo channels below this are not divided out (a black surface's lighting is unknown, and
/// dividing by almost nothing would turn its noise into fireflies): filtered as they are.
constexpr float kMinAlbedo = 1e-3f;

/// Taps whose exponent exceeds this weigh less than e^−30 ≈ 1e−13 against the centre's
/// kernel-weight 9/64: they are skipped without calling exp.
constexpr float kMaxExponent = 30.0f;

/// The B3-spline scaling function of the à-trous transform, per axis (the 5×5 kernel is the
/// outer product).
constexpr std::array<float, 5> kB3 = {1.0f / 16.0f, 1.0f / 4.0f, 3.0f / 8.0f, 1.0f / 4.0f,
                                      1.0f / 16.0f};

bool finite(const vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// The albedo a channel is divided by: itself, or 1 where it is (nearly) black or not finite.
float demodulator(float albedo) {
  return albedo >= kMinAlbedo && std::isfinite(albedo) ? albedo : 1.0f;
}
vec3 demodulator(const vec3& albedo) {
  return vec3(demodulator(albedo.x), demodulator(albedo.y), demodulator(albedo.z));
}

void check_sigma(float sigma, const char* name) {
  // +inf is allowed: it turns the weight off (exp(−d²/∞) = 1).
  if (!(sigma > 0.0f))
    throw Error(std::string("atrous_denoise: ") + name + " must be positive, got " +
                std::to_string(sigma));
}

/// The image's per-pixel state that does not change across levels.
struct Pixels {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  /// A hit with a finite colour and normal: filtered and used as a tap.
  std::vector<std::uint8_t> usable;
  std::vector<vec3> normal;
  std::vector<float> depth;
  /// Per axis, the centre's depth change per pixel: of the two one-sided differences to usable
  /// neighbours, the smaller in magnitude, so a pixel beside an edge takes its own surface's slope.
  std::vector<vec2> depth_gradient;
};

float one_sided_slope(const Pixels& px, std::size_t i, std::ptrdiff_t before, bool has_before,
                      std::ptrdiff_t after, bool has_after) {
  const float d = px.depth[i];
  const bool b = has_before && px.usable[std::size_t(std::ptrdiff_t(i) + before)] != 0;
  const bool a = has_after && px.usable[std::size_t(std::ptrdiff_t(i) + after)] != 0;
  const float slope_before = b ? d - px.depth[std::size_t(std::ptrdiff_t(i) + before)] : 0.0f;
  const float slope_after = a ? px.depth[std::size_t(std::ptrdiff_t(i) + after)] - d : 0.0f;
  if (a && b) return std::abs(slope_before) <= std::abs(slope_after) ? slope_before : slope_after;
  return b ? slope_before : slope_after;
}

/// One level of the edge-avoiding à-trous transform: taps `step` pixels apart.
void filter_level(const Pixels& px, const std::vector<vec3>& in, std::vector<vec3>& out,
                  std::uint32_t step, float inv_sigma_color2, float inv_sigma_normal2,
                  float inv_sigma_depth, std::uint32_t y0, std::uint32_t y1) {
  const int w = int(px.width);
  const int h = int(px.height);
  const int s = int(step);
  for (int y = int(y0); y < int(y1); ++y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t p = std::size_t(y) * std::size_t(w) + std::size_t(x);
      if (px.usable[p] == 0) {
        out[p] = in[p];
        continue;
      }
      const vec3 c_p = in[p];
      const vec3 n_p = px.normal[p];
      const float d_p = px.depth[p];
      const vec2 g_p = px.depth_gradient[p];
      // Depth is compared relative to the centre's (perspective makes absolute scales useless).
      const float inv_depth_scale = inv_sigma_depth / std::max(d_p, 1e-20f);
      // The centre weighs its kernel weight alone (all distances 0), so weight_sum ≥ 9/64.
      constexpr float kCentre = kB3[2] * kB3[2];
      vec3 sum = kCentre * c_p;
      float weight_sum = kCentre;
      for (int j = -2; j <= 2; ++j) {
        const int qy = y + j * s;
        if (qy < 0 || qy >= h) continue;
        for (int i = -2; i <= 2; ++i) {
          const int qx = x + i * s;
          if (qx < 0 || qx >= w) continue;
          const std::size_t q = std::size_t(qy) * std::size_t(w) + std::size_t(qx);
          if (px.usable[q] == 0 || (i == 0 && j == 0)) continue;
          const vec3 dc = in[q] - c_p;
          const vec3 dn = px.normal[q] - n_p;
          const float predicted = d_p + g_p.x * float(i * s) + g_p.y * float(j * s);
          const float dd = (px.depth[q] - predicted) * inv_depth_scale;
          const float exponent =
              glm::dot(dc, dc) * inv_sigma_color2 + glm::dot(dn, dn) * inv_sigma_normal2 + dd * dd;
          if (exponent > kMaxExponent) continue;
          const float weight =
              kB3[std::size_t(i + 2)] * kB3[std::size_t(j + 2)] * std::exp(-exponent);
          sum += weight * in[q];
          weight_sum += weight;
        }
      }
      out[p] = sum / weight_sum;
    }
  }
}

} // namespace

void atrous_denoise(const Framebuffer& noisy, const GuideBuffers& guides,
                    const DenoiseSettings& settings, Framebuffer& out) {
  const std::uint32_t width = noisy.width();
  const std::uint32_t height = noisy.height();
  const std::size_t n = noisy.pixel_count();
  const auto check_size = [&](std::size_t size, const char* name) {
    if (size != n)
      throw Error(std::string("atrous_denoise: the ") + name + " guide has " +
                  std::to_string(size) + " pixels, the image " + std::to_string(width) + "×" +
                  std::to_string(height) + " = " + std::to_string(n));
  };
  check_size(guides.albedo.size(), "albedo");
  check_size(guides.normal.size(), "normal");
  check_size(guides.depth.size(), "depth");
  if (settings.iterations > kMaxIterations)
    throw Error("atrous_denoise: at most " + std::to_string(kMaxIterations) + " iterations, got " +
                std::to_string(settings.iterations));
  check_sigma(settings.sigma_color, "sigma_color");
  check_sigma(settings.sigma_normal, "sigma_normal");
  check_sigma(settings.sigma_depth, "sigma_depth");

  // Everything is read out of `noisy` before `out` is written, so the two may be one image.
  Pixels px;
  px.width = width;
  px.height = height;
  px.usable.resize(n);
  px.normal = guides.normal;
  px.depth = guides.depth;
  px.depth_gradient.resize(n);
  std::vector<vec3> demodulators(n);
  std::vector<vec3> current(n);
  const std::span<const vec3> colour = noisy.pixels();
  for (std::size_t p = 0; p < n; ++p) {
    px.usable[p] = std::isfinite(px.depth[p]) && finite(colour[p]) && finite(px.normal[p]) ? 1 : 0;
    demodulators[p] = demodulator(guides.albedo[p]);
    current[p] = px.usable[p] != 0 ? colour[p] / demodulators[p] : colour[p];
  }
  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      const std::size_t p = std::size_t(y) * width + x;
      if (px.usable[p] == 0) continue;
      const auto row = std::ptrdiff_t(width);
      px.depth_gradient[p] = vec2(one_sided_slope(px, p, -1, x > 0, 1, x + 1 < width),
                                  one_sided_slope(px, p, -row, y > 0, row, y + 1 < height));
    }
  }

  std::vector<vec3> next(n);
  const float inv_sigma_normal2 = 1.0f / (settings.sigma_normal * settings.sigma_normal);
  const float inv_sigma_depth = 1.0f / settings.sigma_depth;
  const int workers = settings.threads > 0 ? int(settings.threads)
                                           : int(std::max(1u, std::thread::hardware_concurrency()));
  tbb::task_arena arena(workers);
  for (std::uint32_t level = 0; level < settings.iterations; ++level) {
    const float sigma_color = std::ldexp(settings.sigma_color, -int(level));
    const float inv_sigma_color2 = 1.0f / (sigma_color * sigma_color);
    const std::uint32_t step = 1u << level;
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, height, 4),
                        [&](const tbb::blocked_range<std::uint32_t>& rows) {
                          filter_level(px, current, next, step, inv_sigma_color2, inv_sigma_normal2,
                                       inv_sigma_depth, rows.begin(), rows.end());
                        });
    });
    current.swap(next);
  }

  out = Framebuffer(width, height);
  const std::span<vec3> result = out.pixels();
  for (std::size_t p = 0; p < n; ++p)
    result[p] = px.usable[p] != 0 ? current[p] * demodulators[p] : current[p];
}

} // namespace specula
