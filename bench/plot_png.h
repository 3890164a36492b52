#pragma once
// A tiny PNG plotter for the bench reports: scatter and line plots with axes, tick labels and a
// legend, drawn into an RGB canvas with a hand-written 3×5 bitmap font and written with
// stb_image_write (no plotting library on the build machines).

#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

namespace specula::bench {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
};

enum class Marker { Circle, Square, TriangleUp, Diamond, Cross, Plus, TriangleDown };

struct PlotPoint {
  double x = 0.0, y = 0.0;
  Rgb colour;
  Marker marker = Marker::Circle;
};

struct PlotSeries { ///< a polyline (points joined in order), drawn under the markers
  std::vector<std::pair<double, double>> points;
  Rgb colour;
  Marker marker = Marker::Circle;
};

struct LegendEntry {
  std::string text; ///< upper-cased when drawn; letters, digits and . - + _ : ( ) / % = only
  Rgb colour;
  Marker marker = Marker::Circle;
};

struct Plot {
  std::string title, x_label, y_label;
  std::vector<PlotPoint> points;
  std::vector<PlotSeries> series;
  std::vector<LegendEntry> legend;
  /// Horizontal reference line (e.g. speed-up 1); NaN: none.
  double y_reference = kNaN;
  /// Fixed axis ranges; NaN: from the data.
  double x_min = kNaN, x_max = kNaN, y_min = kNaN, y_max = kNaN;
  /// Fixed tick steps; NaN: a 1-2-5 step giving about eight ticks.
  double x_step = kNaN, y_step = kNaN;
  std::uint32_t width = 960, height = 640;
};

/// Draws the plot and writes it as a PNG; throws std::runtime_error when writing fails.
void write_plot_png(const Plot& plot, const std::filesystem::path& path);

} // namespace specula::bench
