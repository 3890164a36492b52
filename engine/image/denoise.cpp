#include "specula/image/denoise.h"

#include "specula/core/error.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <utility>

namespace specula {
namespace {

/// Most levels: at 12 the footprint (4·(2^12 − 1) + 1 pixels) already spans the largest
/// framebuffer.
constexpr std::uint32_t kMaxIterations = 12;

/// Albedo channels below this are not divided out (a black surface's lighting is unknown, and
/// dividing by almost nothing would turn its noise into fireflies): filtered as they are.
constexpr float kMinAlbedo = 1e-3f;

/// Taps whose exponent exceeds this weigh less than e^−30 ≈ 1e−13 against the centre's
/// kernel weight 9/64: they get weight 0 (and the exponential never sees a huge argument).
constexpr float kMaxExponent = 30.0f;

/// The B3-spline scaling function of the à-trous transform, per axis (the 5×5 kernel is the
/// outer product).
constexpr std::array<float, 5> kB3 = {1.0f / 16.0f, 1.0f / 4.0f, 3.0f / 8.0f, 1.0f / 4.0f,
                                      1.0f / 16.0f};

/// Pixels per SIMD step of the widest kernel (AVX2): rows are padded to a multiple of it.
constexpr std::uint32_t kRowLanes = 8;

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

/// One float per pixel, rows `stride` apart, each row with `pad` columns of zeros on either side:
/// every tap of the widest level lands inside the buffer, and a padding tap is never usable.
struct Plane {
  std::vector<float> data;
  float* row(std::size_t y, std::size_t stride, std::size_t pad) {
    return data.data() + y * stride + pad;
  }
  [[nodiscard]] const float* row(std::size_t y, std::size_t stride, std::size_t pad) const {
    return data.data() + y * stride + pad;
  }
};

/// The per-pixel state the levels share (guides, in planes), and the colour planes they
/// ping-pong between.
struct Planes {
  std::size_t width = 0, height = 0, stride = 0, pad = 0;
  /// 1 for a hit with a finite colour and normal (filtered and used as a tap), else 0; the other
  /// planes hold 0 there, so a weight of 0 times them is 0, never NaN.
  Plane usable;
  Plane nx, ny, nz;
  Plane depth;
  /// The centre's expected depth change per pixel, per axis: of the two one-sided differences to
  /// usable neighbours, the smaller in magnitude, so a pixel beside an edge takes its own
  /// surface's slope.
  Plane slope_x, slope_y;
  /// 1 / (σ_depth · depth): depth differences are relative to the centre's depth.
  Plane inv_depth_scale;
  std::array<Plane, 3> colour, next;
  /// Variance-guided only: the variance of each pixel's current estimate, and the next level's.
  Plane variance, next_variance;

  void allocate(std::size_t w, std::size_t h, std::size_t padding, bool with_variance) {
    width = w;
    height = h;
    pad = padding;
    stride = pad + (w + kRowLanes - 1) / kRowLanes * kRowLanes + pad;
    for (Plane* p : {&usable, &nx, &ny, &nz, &depth, &slope_x, &slope_y, &inv_depth_scale,
                     &colour[0], &colour[1], &colour[2], &next[0], &next[1], &next[2]})
      p->data.assign(stride * h, 0.0f);
    if (with_variance)
      for (Plane* p : {&variance, &next_variance}) p->data.assign(stride * h, 0.0f);
  }
  float& at(Plane& p, std::size_t x, std::size_t y) const { return p.row(y, stride, pad)[x]; }
  [[nodiscard]] float at(const Plane& p, std::size_t x, std::size_t y) const {
    return p.row(y, stride, pad)[x];
  }
};

/// The largest variance the planes hold: an unknown one (+inf) is stored as this, so the
/// weighted sums of variances stay finite (a weight of 0 times it is 0, never NaN) and its colour
/// weight is 1 to float precision.
constexpr float kUnknownVariance = 1e30f;

/// Added to σ_v²·Var before it is inverted: a converged pixel (Var 0) takes only taps of its
/// exact colour, and the inverse stays finite.
constexpr float kVarianceFloor = 1e-30f;

// One level of the filter (denoise_level.inl), written once over a few vector operations and
// compiled twice: for SSE2 (the x86-64 baseline, 4 pixels a step) and, in functions with the avx2
// target attribute, for AVX2 (8 pixels), chosen at run time. Every lane runs the same IEEE
// operations in the same order (no FMA), so both give the same bits.
namespace sse {
constexpr std::size_t kLanes = 4;
using Vf = __m128;
#define SPECULA_SIMD_TARGET
SPECULA_SIMD_TARGET inline Vf vset1(float x) { return _mm_set1_ps(x); }
SPECULA_SIMD_TARGET inline Vf vzero() { return _mm_setzero_ps(); }
SPECULA_SIMD_TARGET inline Vf vload(const float* p) { return _mm_loadu_ps(p); }
SPECULA_SIMD_TARGET inline void vstore(float* p, Vf a) { _mm_storeu_ps(p, a); }
SPECULA_SIMD_TARGET inline Vf vadd(Vf a, Vf b) { return _mm_add_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vsub(Vf a, Vf b) { return _mm_sub_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmul(Vf a, Vf b) { return _mm_mul_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vdiv(Vf a, Vf b) { return _mm_div_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmin(Vf a, Vf b) { return _mm_min_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vlt(Vf a, Vf b) { return _mm_cmplt_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vand(Vf a, Vf b) { return _mm_and_ps(a, b); }
/// 2^(n − 1) of t's integer part n (toward zero) and t − n + 1 ∈ (0, 1], for exp_neg.
SPECULA_SIMD_TARGET inline void vsplit(Vf t, Vf& power, Vf& g) {
  const __m128i n = _mm_cvttps_epi32(t);
  g = _mm_add_ps(_mm_sub_ps(t, _mm_cvtepi32_ps(n)), _mm_set1_ps(1.0f));
  power = _mm_castsi128_ps(_mm_slli_epi32(_mm_add_epi32(n, _mm_set1_epi32(126)), 23));
}
#include "denoise_level.inl"
#undef SPECULA_SIMD_TARGET
} // namespace sse

namespace avx2 {
constexpr std::size_t kLanes = 8;
using Vf = __m256;
#define SPECULA_SIMD_TARGET __attribute__((target("avx2")))
SPECULA_SIMD_TARGET inline Vf vset1(float x) { return _mm256_set1_ps(x); }
SPECULA_SIMD_TARGET inline Vf vzero() { return _mm256_setzero_ps(); }
SPECULA_SIMD_TARGET inline Vf vload(const float* p) { return _mm256_loadu_ps(p); }
SPECULA_SIMD_TARGET inline void vstore(float* p, Vf a) { _mm256_storeu_ps(p, a); }
SPECULA_SIMD_TARGET inline Vf vadd(Vf a, Vf b) { return _mm256_add_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vsub(Vf a, Vf b) { return _mm256_sub_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmul(Vf a, Vf b) { return _mm256_mul_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vdiv(Vf a, Vf b) { return _mm256_div_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmin(Vf a, Vf b) { return _mm256_min_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vlt(Vf a, Vf b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
SPECULA_SIMD_TARGET inline Vf vand(Vf a, Vf b) { return _mm256_and_ps(a, b); }
SPECULA_SIMD_TARGET inline void vsplit(Vf t, Vf& power, Vf& g) {
  const __m256i n = _mm256_cvttps_epi32(t);
  g = _mm256_add_ps(_mm256_sub_ps(t, _mm256_cvtepi32_ps(n)), _mm256_set1_ps(1.0f));
  power = _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(n, _mm256_set1_epi32(126)), 23));
}
#include "denoise_level.inl"
#undef SPECULA_SIMD_TARGET
} // namespace avx2

/// The variance plane from the caller's variances: each usable pixel gets the 3×3 binomial mean
/// (1 2 1 per axis) of its usable neighbours' variances — an estimate from a few frames is itself
/// noisy — with unknown ones (+inf, NaN, negative) clamped to kUnknownVariance.
void prefilter_variance(Planes& px, const std::vector<std::uint8_t>& usable,
                        std::span<const float> variance) {
  const std::size_t w = px.width, h = px.height;
  const auto known = [](float v) {
    return v >= 0.0f ? std::min(v, kUnknownVariance) : kUnknownVariance;
  };
  for (std::size_t y = 0; y < h; ++y)
    for (std::size_t x = 0; x < w; ++x) {
      if (usable[y * w + x] == 0) continue;
      double sum = 0.0, weights = 0.0;
      for (std::ptrdiff_t j = -1; j <= 1; ++j)
        for (std::ptrdiff_t i = -1; i <= 1; ++i) {
          const std::ptrdiff_t qx = std::ptrdiff_t(x) + i, qy = std::ptrdiff_t(y) + j;
          if (qx < 0 || qy < 0 || qx >= std::ptrdiff_t(w) || qy >= std::ptrdiff_t(h)) continue;
          const std::size_t q = std::size_t(qy) * w + std::size_t(qx);
          if (usable[q] == 0) continue;
          const double k = double((2 - std::abs(i)) * (2 - std::abs(j)));
          sum += k * double(known(variance[q]));
          weights += k;
        }
      px.at(px.variance, x, y) = float(sum / weights);
    }
}

/// One level over rows [y0, y1) with the kernel of `lanes` (4: SSE2, 8: AVX2).
void filter_rows(Planes& px, std::uint32_t lanes, bool guided, std::uint32_t step,
                 float inv_sigma_color2, float inv_sigma_normal2, std::size_t y0, std::size_t y1) {
  if (lanes == 8) {
    if (guided)
      avx2::filter_level<true>(px, step, inv_sigma_color2, inv_sigma_normal2, y0, y1);
    else
      avx2::filter_level<false>(px, step, inv_sigma_color2, inv_sigma_normal2, y0, y1);
  } else {
    if (guided)
      sse::filter_level<true>(px, step, inv_sigma_color2, inv_sigma_normal2, y0, y1);
    else
      sse::filter_level<false>(px, step, inv_sigma_color2, inv_sigma_normal2, y0, y1);
  }
}

/// Of the one-sided depth differences towards usable neighbours, the smaller in magnitude.
float slope(float before, bool has_before, float centre, float after, bool has_after) {
  const float b = centre - before, a = after - centre;
  if (has_before && has_after) return std::abs(b) <= std::abs(a) ? b : a;
  return has_before ? b : has_after ? a : 0.0f;
}

/// Rec. 709 luminance.
float luminance(const vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

} // namespace

void LuminanceMoments::reset(std::size_t pixels) {
  sum_.assign(pixels, 0.0);
  sum2_.assign(pixels, 0.0);
  count_.assign(pixels, 0);
  frames_ = 0;
}

void LuminanceMoments::add(const Framebuffer& frame, const GuideBuffers& guides) {
  const std::size_t n = sum_.size();
  if (frame.pixel_count() != n || guides.albedo.size() != n)
    throw Error("luminance moments: a frame of " + std::to_string(frame.pixel_count()) +
                " pixels with guides of " + std::to_string(guides.albedo.size()) +
                ", reset() was given " + std::to_string(n));
  const std::span<const vec3> c = frame.pixels();
  for (std::size_t i = 0; i < n; ++i) {
    const float l = luminance(c[i] / demodulator(guides.albedo[i]));
    if (!std::isfinite(l)) continue;
    sum_[i] += double(l);
    sum2_[i] += double(l) * double(l);
    ++count_[i];
  }
  ++frames_;
}

std::vector<float> LuminanceMoments::variance_of_mean() const {
  if (frames_ < 2) return {};
  std::vector<float> out(sum_.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double k = double(count_[i]);
    if (count_[i] < 2) {
      out[i] = std::numeric_limits<float>::infinity();
      continue;
    }
    const double mean = sum_[i] / k;
    // The sample variance (k − 1 in the denominator), of the mean: over k once more.
    const double var = std::max(0.0, (sum2_[i] - k * mean * mean) / (k - 1.0));
    out[i] = float(var / k);
  }
  return out;
}

void atrous_denoise(const Framebuffer& noisy, const GuideBuffers& guides,
                    const DenoiseSettings& settings, Framebuffer& out,
                    std::span<const float> variance) {
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
  if (settings.lanes != 0 && settings.lanes != 4 && settings.lanes != 8)
    throw Error("atrous_denoise: lanes must be 0, 4 or 8, got " + std::to_string(settings.lanes));
  static const bool has_avx2 = __builtin_cpu_supports("avx2");
  if (settings.lanes == 8 && !has_avx2)
    throw Error("atrous_denoise: 8 lanes need AVX2, which this CPU does not have");
  const std::uint32_t lanes = settings.lanes != 0 ? settings.lanes : has_avx2 ? 8u : 4u;
  const bool guided = !variance.empty();
  if (guided) {
    check_size(variance.size(), "variance");
    if (!(settings.sigma_variance > 0.0f) || !std::isfinite(settings.sigma_variance))
      throw Error("atrous_denoise: sigma_variance must be positive and finite, got " +
                  std::to_string(settings.sigma_variance));
  }

  // Everything is read out of `noisy` before `out` is written, so the two may be one image.
  // Padding: the widest level's farthest tap (2 · 2^(levels−1)), rounded up to whole lanes;
  // a tap farther than the image is wide is skipped instead.
  const std::size_t reach =
      settings.iterations == 0 ? 0 : std::size_t(2) << (settings.iterations - 1);
  Planes px;
  px.allocate(width, height,
              (std::min<std::size_t>(reach, width) + kRowLanes - 1) / kRowLanes * kRowLanes,
              guided);
  const std::span<const vec3> colour = noisy.pixels();
  std::vector<vec3> demodulators(n);
  std::vector<std::uint8_t> usable(n);
  const float inv_sigma_depth = 1.0f / settings.sigma_depth;
  for (std::size_t y = 0; y < height; ++y)
    for (std::size_t x = 0; x < width; ++x) {
      const std::size_t p = y * width + x;
      usable[p] = std::isfinite(guides.depth[p]) && finite(colour[p]) && finite(guides.normal[p]);
      if (usable[p] == 0) continue;
      demodulators[p] = demodulator(guides.albedo[p]);
      const vec3 lighting = colour[p] / demodulators[p];
      px.at(px.usable, x, y) = 1.0f;
      px.at(px.colour[0], x, y) = lighting.x;
      px.at(px.colour[1], x, y) = lighting.y;
      px.at(px.colour[2], x, y) = lighting.z;
      px.at(px.nx, x, y) = guides.normal[p].x;
      px.at(px.ny, x, y) = guides.normal[p].y;
      px.at(px.nz, x, y) = guides.normal[p].z;
      px.at(px.depth, x, y) = guides.depth[p];
      px.at(px.inv_depth_scale, x, y) = inv_sigma_depth / std::max(guides.depth[p], 1e-20f);
    }
  for (std::size_t y = 0; y < height; ++y)
    for (std::size_t x = 0; x < width; ++x) {
      const std::size_t p = y * width + x;
      if (usable[p] == 0) continue;
      const float d = guides.depth[p];
      const bool left = x > 0 && usable[p - 1] != 0, right = x + 1 < width && usable[p + 1] != 0;
      const bool up = y > 0 && usable[p - width] != 0;
      const bool down = y + 1 < height && usable[p + width] != 0;
      px.at(px.slope_x, x, y) = slope(left ? guides.depth[p - 1] : 0.0f, left, d,
                                      right ? guides.depth[p + 1] : 0.0f, right);
      px.at(px.slope_y, x, y) = slope(up ? guides.depth[p - width] : 0.0f, up, d,
                                      down ? guides.depth[p + width] : 0.0f, down);
    }

  if (guided) prefilter_variance(px, usable, variance);

  const float inv_sigma_normal2 = 1.0f / (settings.sigma_normal * settings.sigma_normal);
  const int workers = settings.threads > 0 ? int(settings.threads)
                                           : int(std::max(1u, std::thread::hardware_concurrency()));
  tbb::task_arena arena(workers);
  for (std::uint32_t level = 0; level < settings.iterations; ++level) {
    // The fixed weight's σ is halved per level; the variance-guided one shrinks with the
    // variance it carries.
    const float sigma_color =
        guided ? settings.sigma_variance : std::ldexp(settings.sigma_color, -int(level));
    const float inv_sigma_color2 = 1.0f / (sigma_color * sigma_color);
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, height, 4),
                        [&](const tbb::blocked_range<std::size_t>& rows) {
                          filter_rows(px, lanes, guided, 1u << level, inv_sigma_color2,
                                      inv_sigma_normal2, rows.begin(), rows.end());
                        });
    });
    px.colour.swap(px.next);
    std::swap(px.variance, px.next_variance);
  }

  Framebuffer result(width, height);
  for (std::size_t y = 0; y < height; ++y)
    for (std::size_t x = 0; x < width; ++x) {
      const std::size_t p = y * width + x;
      result.pixels()[p] = usable[p] == 0
                               ? colour[p]
                               : vec3(px.at(px.colour[0], x, y), px.at(px.colour[1], x, y),
                                      px.at(px.colour[2], x, y)) *
                                     demodulators[p];
    }
  out = std::move(result); // only now: `colour` may be out's own pixels
}

} // namespace specula
