#include "plot_png.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wold-style-cast"
#pragma GCC diagnostic ignored "-Wcast-align"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#endif
// Static: the engine library defines stb's functions too (engine/image/image_io.cpp).
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace specula::bench {
namespace {

/// 3×5 glyphs, rows top to bottom, '#' lit.
struct Glyph {
  char c;
  const char* rows[5];
};
constexpr Glyph kFont[] = {
    {'0', {"###", "#.#", "#.#", "#.#", "###"}}, {'1', {".#.", "##.", ".#.", ".#.", "###"}},
    {'2', {"###", "..#", "###", "#..", "###"}}, {'3', {"###", "..#", "###", "..#", "###"}},
    {'4', {"#.#", "#.#", "###", "..#", "..#"}}, {'5', {"###", "#..", "###", "..#", "###"}},
    {'6', {"###", "#..", "###", "#.#", "###"}}, {'7', {"###", "..#", "..#", "..#", "..#"}},
    {'8', {"###", "#.#", "###", "#.#", "###"}}, {'9', {"###", "#.#", "###", "..#", "###"}},
    {'A', {".#.", "#.#", "###", "#.#", "#.#"}}, {'B', {"##.", "#.#", "##.", "#.#", "##."}},
    {'C', {"###", "#..", "#..", "#..", "###"}}, {'D', {"##.", "#.#", "#.#", "#.#", "##."}},
    {'E', {"###", "#..", "##.", "#..", "###"}}, {'F', {"###", "#..", "##.", "#..", "#.."}},
    {'G', {"###", "#..", "#.#", "#.#", "###"}}, {'H', {"#.#", "#.#", "###", "#.#", "#.#"}},
    {'I', {"###", ".#.", ".#.", ".#.", "###"}}, {'J', {"..#", "..#", "..#", "#.#", "###"}},
    {'K', {"#.#", "#.#", "##.", "#.#", "#.#"}}, {'L', {"#..", "#..", "#..", "#..", "###"}},
    {'M', {"#.#", "###", "###", "#.#", "#.#"}}, {'N', {"##.", "#.#", "#.#", "#.#", "#.#"}},
    {'O', {".#.", "#.#", "#.#", "#.#", ".#."}}, {'P', {"###", "#.#", "###", "#..", "#.."}},
    {'Q', {"###", "#.#", "#.#", "###", "..#"}}, {'R', {"##.", "#.#", "##.", "#.#", "#.#"}},
    {'S', {"###", "#..", "###", "..#", "###"}}, {'T', {"###", ".#.", ".#.", ".#.", ".#."}},
    {'U', {"#.#", "#.#", "#.#", "#.#", "###"}}, {'V', {"#.#", "#.#", "#.#", "#.#", ".#."}},
    {'W', {"#.#", "#.#", "###", "###", "#.#"}}, {'X', {"#.#", "#.#", ".#.", "#.#", "#.#"}},
    {'Y', {"#.#", "#.#", ".#.", ".#.", ".#."}}, {'Z', {"###", "..#", ".#.", "#..", "###"}},
    {'.', {"...", "...", "...", "...", ".#."}}, {'-', {"...", "...", "###", "...", "..."}},
    {'+', {"...", ".#.", "###", ".#.", "..."}}, {'_', {"...", "...", "...", "...", "###"}},
    {':', {"...", ".#.", "...", ".#.", "..."}}, {'(', {".#.", "#..", "#..", "#..", ".#."}},
    {')', {".#.", "..#", "..#", "..#", ".#."}}, {'/', {"..#", "..#", ".#.", "#..", "#.."}},
    {'%', {"#.#", "..#", ".#.", "#..", "#.#"}}, {'=', {"...", "###", "...", "###", "..."}},
    {',', {"...", "...", "...", ".#.", "#.."}},
};

const Glyph* glyph(char c) {
  c = char(std::toupper(static_cast<unsigned char>(c)));
  for (const Glyph& g : kFont)
    if (g.c == c) return &g;
  return nullptr; // space and anything unknown: blank
}

class Canvas {
public:
  Canvas(std::uint32_t w, std::uint32_t h) : w_(int(w)), h_(int(h)), px_(std::size_t(w) * h * 3, 255) {}

  void set(int x, int y, Rgb c) {
    if (x < 0 || y < 0 || x >= w_ || y >= h_) return;
    std::uint8_t* p = &px_[(std::size_t(y) * std::size_t(w_) + std::size_t(x)) * 3];
    p[0] = c.r;
    p[1] = c.g;
    p[2] = c.b;
  }
  void rect(int x0, int y0, int x1, int y1, Rgb c) {
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) set(x, y, c);
  }
  void line(int x0, int y0, int x1, int y1, Rgb c, int thickness = 1, int dash = 0) {
    const int steps = std::max(std::abs(x1 - x0), std::abs(y1 - y0));
    for (int i = 0; i <= steps; ++i) {
      if (dash > 0 && (i / dash) % 2 == 1) continue;
      const double t = steps == 0 ? 0.0 : double(i) / steps;
      const int x = int(std::lround(x0 + t * (x1 - x0))), y = int(std::lround(y0 + t * (y1 - y0)));
      rect(x - thickness / 2, y - thickness / 2, x + (thickness - 1) / 2, y + (thickness - 1) / 2, c);
    }
  }
  /// Text with its top-left corner at (x, y), each font pixel `scale` canvas pixels.
  void text(int x, int y, const std::string& s, Rgb c, int scale = 2) {
    for (const char ch : s) {
      if (const Glyph* g = glyph(ch))
        for (int r = 0; r < 5; ++r)
          for (int k = 0; k < 3; ++k)
            if (g->rows[r][k] == '#')
              rect(x + k * scale, y + r * scale, x + k * scale + scale - 1,
                   y + r * scale + scale - 1, c);
      x += 4 * scale;
    }
  }
  static int text_width(const std::string& s, int scale = 2) {
    return s.empty() ? 0 : int(s.size()) * 4 * scale - scale;
  }
  void marker(int x, int y, Marker m, Rgb c, int r = 5) {
    switch (m) {
    case Marker::Circle:
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx)
          if (dx * dx + dy * dy <= r * r) set(x + dx, y + dy, c);
      break;
    case Marker::Square: rect(x - r + 1, y - r + 1, x + r - 1, y + r - 1, c); break;
    case Marker::TriangleUp:
    case Marker::TriangleDown:
      for (int dy = -r; dy <= r; ++dy) {
        const int row = m == Marker::TriangleUp ? dy + r : r - dy; // 0 at the apex
        const int half = row / 2;
        for (int dx = -half; dx <= half; ++dx) set(x + dx, y + dy, c);
      }
      break;
    case Marker::Diamond:
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx)
          if (std::abs(dx) + std::abs(dy) <= r) set(x + dx, y + dy, c);
      break;
    case Marker::Cross:
      line(x - r, y - r, x + r, y + r, c, 3);
      line(x - r, y + r, x + r, y - r, c, 3);
      break;
    case Marker::Plus:
      line(x - r, y, x + r, y, c, 3);
      line(x, y - r, x, y + r, c, 3);
      break;
    }
  }
  void write(const std::filesystem::path& path) const {
    if (stbi_write_png(path.string().c_str(), w_, h_, 3, px_.data(), w_ * 3) == 0)
      throw std::runtime_error("cannot write " + path.string());
  }

private:
  int w_, h_;
  std::vector<std::uint8_t> px_;
};

/// A "nice" tick step (1, 2 or 5 × 10^k) giving at most about `max_ticks` ticks over `span`.
double nice_step(double span, int max_ticks) {
  if (!(span > 0.0)) return 1.0;
  const double raw = span / max_ticks;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= raw) return m * p;
  return 10.0 * p;
}

std::string tick_label(double v, double step) {
  const int decimals = step >= 1.0 ? 0 : int(std::ceil(-std::log10(step) - 1e-9));
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, std::abs(v) < step * 1e-6 ? 0.0 : v);
  return buf;
}

} // namespace

void write_plot_png(const Plot& plot, const std::filesystem::path& path) {
  Canvas cv(plot.width, plot.height);
  const Rgb black{0, 0, 0}, grey{200, 200, 200}, dark{90, 90, 90};
  const int left = 80, right = int(plot.width) - 250, top = 50, bottom = int(plot.height) - 60;

  double x0 = plot.x_min, x1 = plot.x_max, y0 = plot.y_min, y1 = plot.y_max;
  auto grow = [](double& lo, double& hi, double v, bool fixed_lo, bool fixed_hi) {
    if (!std::isfinite(v)) return;
    if (!fixed_lo) lo = std::isnan(lo) ? v : std::min(lo, v);
    if (!fixed_hi) hi = std::isnan(hi) ? v : std::max(hi, v);
  };
  const bool fx0 = !std::isnan(plot.x_min), fx1 = !std::isnan(plot.x_max),
             fy0 = !std::isnan(plot.y_min), fy1 = !std::isnan(plot.y_max);
  for (const PlotPoint& p : plot.points) {
    grow(x0, x1, p.x, fx0, fx1);
    grow(y0, y1, p.y, fy0, fy1);
  }
  for (const PlotSeries& s : plot.series)
    for (const auto& [x, y] : s.points) {
      grow(x0, x1, x, fx0, fx1);
      grow(y0, y1, y, fy0, fy1);
    }
  if (!std::isnan(plot.y_reference)) grow(y0, y1, plot.y_reference, fy0, fy1);
  if (std::isnan(x0)) x0 = 0.0, x1 = 1.0;
  if (std::isnan(y0)) y0 = 0.0, y1 = 1.0;
  if (x1 <= x0) x0 -= 0.5, x1 += 0.5;
  if (y1 <= y0) y0 -= 0.05, y1 += 0.05;
  const double xs = std::isnan(plot.x_step) ? nice_step(x1 - x0, 8) : plot.x_step;
  const double ys = std::isnan(plot.y_step) ? nice_step(y1 - y0, 8) : plot.y_step;
  if (!fx0) x0 = std::floor(x0 / xs) * xs;
  if (!fx1) x1 = std::ceil(x1 / xs) * xs;
  if (!fy0) y0 = std::floor(y0 / ys) * ys;
  if (!fy1) y1 = std::ceil(y1 / ys) * ys;
  if (x1 <= x0) x1 = x0 + xs;
  if (y1 <= y0) y1 = y0 + ys;

  const auto px = [&](double x) { return left + int(std::lround((x - x0) / (x1 - x0) * (right - left))); };
  const auto py = [&](double y) { return bottom - int(std::lround((y - y0) / (y1 - y0) * (bottom - top))); };

  // Grid and ticks.
  for (double t = std::ceil(x0 / xs - 1e-9) * xs; t <= x1 + xs * 1e-6; t += xs) {
    const int x = px(t);
    cv.line(x, top, x, bottom, grey);
    cv.line(x, bottom, x, bottom + 5, black);
    const std::string l = tick_label(t, xs);
    cv.text(x - Canvas::text_width(l) / 2, bottom + 10, l, black);
  }
  for (double t = std::ceil(y0 / ys - 1e-9) * ys; t <= y1 + ys * 1e-6; t += ys) {
    const int y = py(t);
    cv.line(left, y, right, y, grey);
    cv.line(left - 5, y, left, y, black);
    const std::string l = tick_label(t, ys);
    cv.text(left - 10 - Canvas::text_width(l), y - 5, l, black);
  }
  if (!std::isnan(plot.y_reference) && plot.y_reference >= y0 && plot.y_reference <= y1)
    cv.line(left, py(plot.y_reference), right, py(plot.y_reference), dark, 1, 6);
  cv.line(left, bottom, right, bottom, black, 2);
  cv.line(left, top, left, bottom, black, 2);

  // Labels.
  cv.text(left, 12, plot.title, black, 3);
  cv.text((left + right) / 2 - Canvas::text_width(plot.x_label) / 2, bottom + 35, plot.x_label, black);
  cv.text(left - 70, top - 18, plot.y_label, black);

  // Data: lines, then markers (points outside a fixed range are clamped to its edge).
  const auto cx = [&](double x) { return px(std::clamp(x, x0, x1)); };
  const auto cy = [&](double y) { return py(std::clamp(y, y0, y1)); };
  for (const PlotSeries& s : plot.series) {
    for (std::size_t i = 1; i < s.points.size(); ++i)
      cv.line(cx(s.points[i - 1].first), cy(s.points[i - 1].second), cx(s.points[i].first),
              cy(s.points[i].second), s.colour, 2);
    for (const auto& [x, y] : s.points) cv.marker(cx(x), cy(y), s.marker, s.colour, 4);
  }
  for (const PlotPoint& p : plot.points)
    if (std::isfinite(p.y)) cv.marker(cx(std::isfinite(p.x) ? p.x : x1), cy(p.y), p.marker, p.colour);

  // Legend.
  int ly = top;
  for (const LegendEntry& e : plot.legend) {
    if (e.text.empty()) {
      ly += 10;
      continue;
    }
    cv.marker(right + 25, ly + 5, e.marker, e.colour);
    cv.text(right + 40, ly, e.text, black);
    ly += 20;
  }
  cv.write(path);
}

} // namespace specula::bench
