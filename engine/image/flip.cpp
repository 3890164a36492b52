// LDR-FLIP, after Andersson et al., "FLIP: A Difference Evaluator for Alternating Images" (HPG
// 2020). Two pipelines run on both images and meet at the end:
//   colour:  linear RGB → YCxCz → CSF spatial filter → L*a*b* → Hunt → HyAB → ΔE_c in [0, 1]
//   feature: achromatic channel → edge and point detectors → ΔE_f in [0, 1]
//   result:  ΔE = ΔE_c^(1 − ΔE_f)
// Filters are applied separably (every kernel here is a sum of products f(x)·g(y)), which gives
// the same result as the paper's square kernels at a fraction of the cost.

#include "specula/image/flip.h"

#include "specula/core/assert.h"
#include "specula/core/error.h"
#include "specula/image/image_io.h"
#include "specula/image/srgb.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <span>
#include <string>

namespace specula {

namespace {

// --- Constants from the paper ------------------------------------------------------------------

constexpr double kQc = 0.7;  ///< q_c: exponent compressing the HyAB colour distance
constexpr double kPc = 0.4;  ///< p_c: errors below p_c·cmax fill the range [0, p_t] ...
constexpr double kPt = 0.95; ///< p_t: ... and larger ones are squeezed into (p_t, 1]
constexpr double kQf = 0.5;  ///< q_f: exponent of the feature difference
/// w: width of the edge and point detectors in degrees; their Gaussian has σ = w/2.
constexpr double kDetectorWidthDegrees = 0.082;

/// One term a·sqrt(π/b)·exp(−π²x²/b) of a contrast sensitivity function, the spatial-domain
/// form of the paper's frequency-domain Gaussian sums (x in degrees). Achromatic and red-green
/// use one Gaussian (their second terms have a = 0); blue-yellow uses two.
struct CsfTerm {
  double a;
  double b;
};
constexpr std::array<CsfTerm, 1> kCsfAchromatic = {{{1.0, 0.0047}}};
constexpr std::array<CsfTerm, 1> kCsfRedGreen = {{{1.0, 0.0053}}};
constexpr std::array<CsfTerm, 2> kCsfBlueYellow = {{{34.1, 0.04}, {13.5, 0.025}}};
/// The largest b of all six terms (including the a = 0 ones, b = 1e-5) sets one radius for all
/// three filters: three standard deviations of the widest Gaussian, σ² = b / (2π²).
constexpr double kCsfMaxB = 0.04;

// --- Colour spaces -----------------------------------------------------------------------------

/// Linear sRGB ↔ CIE XYZ, derived from the sRGB primaries and D65 white point (IEC 61966-2-1)
/// rather than typed in, so that XYZ of RGB white is exactly the reference white used below.
struct ColorSpace {
  glm::mat3 xyz_from_rgb;
  glm::mat3 rgb_from_xyz;
  vec3 white; ///< XYZ of linear RGB (1, 1, 1), Y = 1
};

ColorSpace make_srgb_color_space() {
  const auto xyz_of = [](double x, double y) { return glm::dvec3(x / y, 1.0, (1.0 - x - y) / y); };
  const glm::dmat3 primaries(xyz_of(0.64, 0.33), xyz_of(0.30, 0.60), xyz_of(0.15, 0.06));
  const glm::dvec3 white = xyz_of(0.3127, 0.3290);
  const glm::dvec3 scale = glm::inverse(primaries) * white; // columns scaled so RGB 1 → white
  const glm::dmat3 m(primaries[0] * scale[0], primaries[1] * scale[1], primaries[2] * scale[2]);
  return {glm::mat3(m), glm::mat3(glm::inverse(m)), vec3(m * glm::dvec3(1.0))};
}

const ColorSpace& srgb_space() {
  static const ColorSpace space = make_srgb_color_space();
  return space;
}

/// YCxCz opponent space (Zhang and Wandell's S-CIELAB), the linearized CIELAB in which the
/// paper applies its contrast sensitivity functions.
vec3 xyz_to_ycxcz(vec3 xyz, vec3 white) {
  const vec3 n = xyz / white;
  return {116.0f * n.y - 16.0f, 500.0f * (n.x - n.y), 200.0f * (n.y - n.z)};
}

vec3 ycxcz_to_xyz(vec3 ycxcz, vec3 white) {
  const float y = (ycxcz.x + 16.0f) / 116.0f;
  return vec3(y + ycxcz.y / 500.0f, y, y - ycxcz.z / 200.0f) * white;
}

/// CIE 1976 L*a*b* with the standard piecewise cube root (linear below (6/29)³).
vec3 xyz_to_lab(vec3 xyz, vec3 white) {
  const auto f = [](float t) {
    constexpr float kDelta = 6.0f / 29.0f;
    return t > kDelta * kDelta * kDelta ? std::cbrt(t)
                                        : t / (3.0f * kDelta * kDelta) + 4.0f / 29.0f;
  };
  const vec3 n = xyz / white;
  const float fx = f(n.x);
  const float fy = f(n.y);
  const float fz = f(n.z);
  return {116.0f * fy - 16.0f, 500.0f * (fx - fy), 200.0f * (fy - fz)};
}

/// Hunt effect: chroma is perceived weaker at low luminance, so a* and b* are scaled by L*/100.
vec3 hunt_adjust(vec3 lab) { return {lab.x, 0.01f * lab.x * lab.y, 0.01f * lab.x * lab.z}; }

/// HyAB (Abasi, Amani Tehran and Fairchild 2020), the distance for large colour differences:
/// city-block in lightness plus Euclidean in chroma.
double hyab(vec3 p, vec3 q) {
  const double da = double{p.y} - q.y;
  const double db = double{p.z} - q.z;
  return std::abs(double{p.x} - q.x) + std::sqrt(da * da + db * db);
}

/// Hunt-adjusted L*a*b* of a linear RGB colour already in [0, 1].
vec3 hunt_lab_of_rgb(vec3 rgb, const ColorSpace& space) {
  return hunt_adjust(xyz_to_lab(space.xyz_from_rgb * rgb, space.white));
}

/// cmax: the largest colour distance FLIP maps to 1, that between pure green and pure blue (the
/// most distant pair of sRGB primaries after the Hunt adjustment), compressed by q_c like every
/// other distance.
double max_color_distance(const ColorSpace& space) {
  const vec3 green = hunt_lab_of_rgb(vec3(0.0f, 1.0f, 0.0f), space);
  const vec3 blue = hunt_lab_of_rgb(vec3(0.0f, 0.0f, 1.0f), space);
  return std::pow(hyab(green, blue), kQc);
}

// --- Separable filtering -----------------------------------------------------------------------

/// Rows [first, first + height) of a single-channel image, row-major. FLIP runs over bands of
/// rows (flip()), so the planes of a band hold the band and, for the inputs of the filters, the
/// rows around it that the filters reach.
struct Plane {
  int width = 0;
  int height = 0;
  int first = 0; ///< the image row of local row 0
  std::vector<float> values;

  Plane(int w, int h, int first_row = 0)
      : width(w), height(h), first(first_row), values(static_cast<std::size_t>(w) * h, 0.0f) {}
  float& operator()(int x, int y) { return values[static_cast<std::size_t>(y) * width + x]; }
  float operator()(int x, int y) const { return values[static_cast<std::size_t>(y) * width + x]; }
};

/// Image rows [first, first + rows) of src convolved with kx(x)·ky(y) (odd-length kernels centred
/// on their middle tap), for an image `image_height` rows tall; src must hold every image row
/// those output rows reach. Borders replicate the edge pixel, as the paper's reference code
/// does, so a uniform image stays uniform and the image border itself is never reported as a
/// feature. Each output value is the same sum, in the same order, whatever the band, so a map
/// computed in bands is bit-identical to one computed whole.
Plane convolve_separable(const Plane& src, std::span<const float> kx, std::span<const float> ky,
                         int image_height, int first, int rows) {
  const int rx = static_cast<int>(kx.size() / 2);
  const int ry = static_cast<int>(ky.size() / 2);
  SPECULA_ASSERT(src.first <= std::max(0, first - ry) &&
                 src.first + src.height >= std::min(image_height, first + rows + ry));
  Plane horizontal(src.width, src.height, src.first);
  for (int y = 0; y < src.height; ++y) {
    for (int x = 0; x < src.width; ++x) {
      float sum = 0.0f;
      for (int i = -rx; i <= rx; ++i) {
        sum += kx[static_cast<std::size_t>(i + rx)] * src(std::clamp(x + i, 0, src.width - 1), y);
      }
      horizontal(x, y) = sum;
    }
  }
  Plane out(src.width, rows, first);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < src.width; ++x) {
      float sum = 0.0f;
      for (int j = -ry; j <= ry; ++j) {
        sum += ky[static_cast<std::size_t>(j + ry)] *
               horizontal(x, std::clamp(first + y + j, 0, image_height - 1) - src.first);
      }
      out(x, y) = sum;
    }
  }
  return out;
}

/// One separable piece of a 2D filter: weight · taps(x) · taps(y).
struct SeparableTerm {
  float weight;
  std::vector<float> taps;
};

/// The CSF filter of one opponent channel as a weighted sum of separable Gaussians, normalized
/// so that the whole 2D kernel sums to 1 (the paper normalizes the sampled kernel the same way).
/// exp(−π²(x² + y²)/b) = exp(−π²x²/b)·exp(−π²y²/b), so each term separates exactly.
template <std::size_t N>
std::vector<SeparableTerm> csf_filter(const std::array<CsfTerm, N>& terms, int radius,
                                      double pixels_per_degree) {
  const double pi = std::numbers::pi;
  std::vector<SeparableTerm> filter;
  std::vector<double> raw_sums; // each term's un-normalized 2D kernel sum
  double total = 0.0;
  for (const CsfTerm& term : terms) {
    std::vector<double> g(static_cast<std::size_t>(2 * radius + 1));
    double sum = 0.0;
    for (int i = -radius; i <= radius; ++i) {
      const double x_degrees = i / pixels_per_degree;
      g[static_cast<std::size_t>(i + radius)] = std::exp(-pi * pi * x_degrees * x_degrees / term.b);
      sum += g[static_cast<std::size_t>(i + radius)];
    }
    SeparableTerm piece{0.0f, {}};
    for (double v : g) piece.taps.push_back(static_cast<float>(v / sum));
    const double raw = term.a * std::sqrt(pi / term.b) * sum * sum;
    raw_sums.push_back(raw);
    total += raw;
    filter.push_back(std::move(piece));
  }
  for (std::size_t k = 0; k < filter.size(); ++k) {
    filter[k].weight = static_cast<float>(raw_sums[k] / total);
  }
  return filter;
}

Plane apply_filter(const Plane& src, const std::vector<SeparableTerm>& filter, int image_height,
                   int first, int rows) {
  Plane out(src.width, rows, first);
  for (const SeparableTerm& term : filter) {
    const Plane part = convolve_separable(src, term.taps, term.taps, image_height, first, rows);
    for (std::size_t i = 0; i < out.values.size(); ++i) {
      out.values[i] += term.weight * part.values[i];
    }
  }
  return out;
}

/// The edge and point detectors: first and second derivatives of a Gaussian of σ = w/2 degrees
/// along one axis, times the Gaussian along the other. Positive taps are scaled to sum to 1 and
/// negative ones to −1, so a response lies in [−1, 1] for inputs in [0, 1] and the detectors do
/// not respond to flat regions.
struct Detectors {
  std::vector<float> gaussian;          ///< normalized to sum 1
  std::vector<float> first_derivative;  ///< edges
  std::vector<float> second_derivative; ///< points
};

std::vector<float> normalize_signed(const std::vector<double>& taps) {
  double positive = 0.0;
  double negative = 0.0;
  for (double v : taps) (v > 0.0 ? positive : negative) += std::abs(v);
  std::vector<float> out;
  for (double v : taps) out.push_back(static_cast<float>(v > 0.0 ? v / positive : v / negative));
  return out;
}

Detectors make_detectors(double pixels_per_degree) {
  const double sigma = 0.5 * kDetectorWidthDegrees * pixels_per_degree; // in pixels
  const int radius = static_cast<int>(std::ceil(3.0 * sigma));
  std::vector<double> g;
  std::vector<double> dg;
  std::vector<double> ddg;
  double g_sum = 0.0;
  for (int i = -radius; i <= radius; ++i) {
    const double x = i;
    const double gauss = std::exp(-x * x / (2.0 * sigma * sigma));
    g.push_back(gauss);
    g_sum += gauss;
    dg.push_back(-x * gauss);
    ddg.push_back((x * x / (sigma * sigma) - 1.0) * gauss);
  }
  Detectors d;
  for (double v : g) d.gaussian.push_back(static_cast<float>(v / g_sum));
  d.first_derivative = normalize_signed(dg);
  d.second_derivative = normalize_signed(ddg);
  return d;
}

/// Magnitudes of the edge and point detector responses (the 2D gradient-like vector of the x and
/// y detectors) of one achromatic plane.
struct Features {
  Plane edges;
  Plane points;
};

Features detect_features(const Plane& achromatic, const Detectors& d, int image_height, int first,
                         int rows) {
  const auto convolve = [&](std::span<const float> kx, std::span<const float> ky) {
    return convolve_separable(achromatic, kx, ky, image_height, first, rows);
  };
  const Plane edge_x = convolve(d.first_derivative, d.gaussian);
  const Plane edge_y = convolve(d.gaussian, d.first_derivative);
  const Plane point_x = convolve(d.second_derivative, d.gaussian);
  const Plane point_y = convolve(d.gaussian, d.second_derivative);
  Features f{Plane(achromatic.width, rows, first), Plane(achromatic.width, rows, first)};
  for (std::size_t i = 0; i < f.edges.values.size(); ++i) {
    f.edges.values[i] = std::hypot(edge_x.values[i], edge_y.values[i]);
    f.points.values[i] = std::hypot(point_x.values[i], point_y.values[i]);
  }
  return f;
}

// --- One image's pipelines ---------------------------------------------------------------------

struct Prepared {
  std::array<Plane, 3> lab; ///< Hunt-adjusted L*a*b* after spatial filtering
  Features features;
};

/// Both pipelines of one image for image rows [first, first + rows), from the rows within
/// `halo` of them (the filters' reach).
Prepared prepare(const Framebuffer& image, const std::array<std::vector<SeparableTerm>, 3>& csf,
                 const Detectors& detectors, const ColorSpace& space, int first, int rows,
                 int halo) {
  const int w = static_cast<int>(image.width());
  const int h = static_cast<int>(image.height());
  const int in_first = std::max(0, first - halo);
  const int in_rows = std::min(h, first + rows + halo) - in_first;

  // The LDR display model: what a monitor shows is clamped to [0, 1]; the paper's sRGB → linear
  // step is the identity here because framebuffers are already linear.
  std::array<Plane, 3> ycxcz = {Plane(w, in_rows, in_first), Plane(w, in_rows, in_first),
                                Plane(w, in_rows, in_first)};
  Plane achromatic(w, in_rows, in_first);
  const auto pixels =
      image.pixels().subspan(static_cast<std::size_t>(in_first) * static_cast<std::size_t>(w),
                             static_cast<std::size_t>(in_rows) * static_cast<std::size_t>(w));
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    const vec3 rgb(clamp_unit(pixels[i].r), clamp_unit(pixels[i].g), clamp_unit(pixels[i].b));
    const vec3 v = xyz_to_ycxcz(space.xyz_from_rgb * rgb, space.white);
    for (int c = 0; c < 3; ++c) ycxcz[static_cast<std::size_t>(c)].values[i] = v[c];
    // Feature input: the unfiltered achromatic channel normalized to [0, 1], (Y + 16) / 116.
    achromatic.values[i] = (v.x + 16.0f) / 116.0f;
  }

  // Colour pipeline: filter each opponent channel with its CSF, then back to RGB, clamp (a
  // filtered colour may leave the gamut), and on to Hunt-adjusted L*a*b*.
  const auto filter = [&](std::size_t c) { return apply_filter(ycxcz[c], csf[c], h, first, rows); };
  const std::array<Plane, 3> filtered = {filter(0), filter(1), filter(2)};
  std::array<Plane, 3> lab = {Plane(w, rows, first), Plane(w, rows, first), Plane(w, rows, first)};
  for (std::size_t i = 0; i < lab[0].values.size(); ++i) {
    const vec3 v(filtered[0].values[i], filtered[1].values[i], filtered[2].values[i]);
    vec3 rgb = space.rgb_from_xyz * ycxcz_to_xyz(v, space.white);
    rgb = vec3(clamp_unit(rgb.r), clamp_unit(rgb.g), clamp_unit(rgb.b));
    const vec3 hunt_lab = hunt_lab_of_rgb(rgb, space);
    for (int c = 0; c < 3; ++c) lab[static_cast<std::size_t>(c)].values[i] = hunt_lab[c];
  }
  return {std::move(lab), detect_features(achromatic, detectors, h, first, rows)};
}

/// Colour error redistribution: the q_c-compressed HyAB distance, with [0, p_c·cmax] stretched
/// to [0, p_t] and (p_c·cmax, cmax] squeezed into (p_t, 1], so that the errors people notice
/// use most of the output range.
double redistribute_color_error(double distance, double cmax) {
  const double e = std::pow(distance, kQc);
  const double knee = kPc * cmax;
  return e < knee ? e * (kPt / knee) : kPt + (e - knee) / (cmax - knee) * (1.0 - kPt);
}

// --- Magma -------------------------------------------------------------------------------------

struct MagmaPoint {
  float index; ///< position in the 256-entry table
  vec3 color;
};
/// Entries 0, 16, ..., 240 and 255 of matplotlib's magma table (CC0).
constexpr std::array<MagmaPoint, 17> kMagma = {{
    {0.0f, {0.001462f, 0.000466f, 0.013866f}},
    {16.0f, {0.039608f, 0.031090f, 0.133515f}},
    {32.0f, {0.113094f, 0.065492f, 0.276784f}},
    {48.0f, {0.211718f, 0.061992f, 0.418647f}},
    {64.0f, {0.316654f, 0.071690f, 0.485380f}},
    {80.0f, {0.414709f, 0.110431f, 0.504662f}},
    {96.0f, {0.512831f, 0.148179f, 0.507648f}},
    {112.0f, {0.613617f, 0.181811f, 0.498536f}},
    {128.0f, {0.716387f, 0.214982f, 0.475290f}},
    {144.0f, {0.816914f, 0.255895f, 0.436461f}},
    {160.0f, {0.904281f, 0.319610f, 0.388137f}},
    {176.0f, {0.960949f, 0.418323f, 0.359630f}},
    {192.0f, {0.986700f, 0.535582f, 0.382210f}},
    {208.0f, {0.996096f, 0.653659f, 0.446213f}},
    {224.0f, {0.996898f, 0.769591f, 0.534892f}},
    {240.0f, {0.992440f, 0.884330f, 0.640099f}},
    {255.0f, {0.987053f, 0.991438f, 0.749504f}},
}};

} // namespace

double flip_pixels_per_degree(double distance_m, double width_m, double resolution_x) {
  return distance_m * (resolution_x / width_m) * (std::numbers::pi / 180.0);
}

namespace {

void check_options(const FlipOptions& options) {
  const double ppd = options.pixels_per_degree;
  if (!(ppd > 0.0 && ppd <= 1000.0)) { // also rejects NaN
    throw Error("flip: pixels per degree " + std::to_string(ppd) + " is outside (0, 1000]");
  }
}

/// The CSF filters' radius in pixels: three standard deviations of the widest Gaussian.
int csf_radius(double ppd) {
  const double pi = std::numbers::pi;
  return static_cast<int>(std::ceil(3.0 * std::sqrt(kCsfMaxB / (2.0 * pi * pi)) * ppd));
}

/// How far, in rows, the filters of either pipeline reach.
int filter_halo(double ppd, const Detectors& detectors) {
  return std::max(csf_radius(ppd), static_cast<int>(detectors.gaussian.size() / 2));
}

/// Rows per band: the option, or the whole image for 0.
int band_rows(const FlipOptions& options, std::uint32_t height) {
  return static_cast<int>(options.band_rows == 0 ? height : std::min(options.band_rows, height));
}

} // namespace

std::uint64_t flip_working_bytes(std::uint32_t width, std::uint32_t height,
                                 const FlipOptions& options) {
  check_options(options);
  const std::uint64_t rows = static_cast<std::uint64_t>(band_rows(options, height));
  const std::uint64_t halo = static_cast<std::uint64_t>(
      filter_halo(options.pixels_per_degree, make_detectors(options.pixels_per_degree)));
  // At most: the reference's band result (5 planes of the band) while the test's band is
  // prepared, whose peak is 5 input planes and a horizontal pass over the band and its halo,
  // plus the filtered, L*a*b*, detector and feature planes of the band (about 14): 24 planes of
  // band + 2·halo rows, a bound. Plus the error map.
  const std::uint64_t band_bytes = 24 * (rows + 2 * halo) * width * sizeof(float);
  return std::uint64_t{width} * height * sizeof(float) + band_bytes;
}

FlipResult flip(const Framebuffer& reference, const Framebuffer& test, const FlipOptions& options) {
  if (reference.width() != test.width() || reference.height() != test.height()) {
    throw Error("flip: image sizes differ (" + std::to_string(reference.width()) + "x" +
                std::to_string(reference.height()) + " vs " + std::to_string(test.width()) + "x" +
                std::to_string(test.height()) + ")");
  }
  check_options(options);
  const double ppd = options.pixels_per_degree;

  const ColorSpace& space = srgb_space();
  const int radius = csf_radius(ppd);
  const std::array<std::vector<SeparableTerm>, 3> csf = {csf_filter(kCsfAchromatic, radius, ppd),
                                                         csf_filter(kCsfRedGreen, radius, ppd),
                                                         csf_filter(kCsfBlueYellow, radius, ppd)};
  const Detectors detectors = make_detectors(ppd);
  const int halo = filter_halo(ppd, detectors);
  const double cmax = max_color_distance(space);

  FlipResult result;
  result.width = reference.width();
  result.height = reference.height();
  result.error_map.resize(reference.pixel_count());
  const int height = static_cast<int>(reference.height());
  const int band = band_rows(options, reference.height());
  double sum = 0.0; // over pixels in row-major order, whatever the band height
  for (int first = 0; first < height; first += band) {
    const int rows = std::min(band, height - first);
    const Prepared ref = prepare(reference, csf, detectors, space, first, rows, halo);
    const Prepared tst = prepare(test, csf, detectors, space, first, rows, halo);
    float* const out = result.error_map.data() + static_cast<std::size_t>(first) * result.width;
    for (std::size_t i = 0; i < ref.lab[0].values.size(); ++i) {
      const vec3 lab_ref(ref.lab[0].values[i], ref.lab[1].values[i], ref.lab[2].values[i]);
      const vec3 lab_tst(tst.lab[0].values[i], tst.lab[1].values[i], tst.lab[2].values[i]);
      const double color_error = redistribute_color_error(hyab(lab_ref, lab_tst), cmax);

      // Feature difference: the larger of the edge and point magnitude differences; each
      // magnitude is at most √2, hence the 1/√2 that maps the difference into [0, 1].
      const double edge_diff =
          std::abs(double{ref.features.edges.values[i]} - tst.features.edges.values[i]);
      const double point_diff =
          std::abs(double{ref.features.points.values[i]} - tst.features.points.values[i]);
      const double feature_error =
          std::pow(std::max(edge_diff, point_diff) / std::numbers::sqrt2, kQf);

      // Features amplify colour errors: an exponent below 1 raises a value in [0, 1]. The clamp
      // only absorbs rounding (both terms are in [0, 1] by construction).
      const double error = std::clamp(std::pow(color_error, 1.0 - feature_error), 0.0, 1.0);
      out[i] = static_cast<float>(error);
      sum += error;
    }
  }
  result.mean = sum / static_cast<double>(result.error_map.size());
  return result;
}

vec3 magma(float t) {
  const float index = clamp_unit(t) * 255.0f;
  for (std::size_t k = 1; k < kMagma.size(); ++k) {
    if (index <= kMagma[k].index) {
      const MagmaPoint& lo = kMagma[k - 1];
      const MagmaPoint& hi = kMagma[k];
      return glm::mix(lo.color, hi.color, (index - lo.index) / (hi.index - lo.index));
    }
  }
  return kMagma.back().color;
}

void write_flip_heatmap(const FlipResult& result, const std::filesystem::path& path) {
  (void)check_image_output_path(path, {ImageFormat::Png}); // PNG bytes only under a .png name
  std::vector<std::uint8_t> rgb;
  rgb.reserve(3 * result.error_map.size());
  for (float e : result.error_map) {
    const vec3 c = magma(e);
    for (int k = 0; k < 3; ++k) rgb.push_back(static_cast<std::uint8_t>(c[k] * 255.0f + 0.5f));
  }
  write_png_srgb8(rgb, result.width, result.height, path);
}

} // namespace specula
