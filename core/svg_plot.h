// Minimal SVG line/scatter plots for reports (no plotting library on the dependency
// list does this in C++; the files open in any browser).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace mcms {

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;
  std::string color = "#1f77b4";
  bool points = false;  // markers instead of a line
  // Optional band drawn as a translucent area around the series (e.g. the predicted
  // +-3 sigma next to the measured values): y_low[i]..y_high[i] at x[i]; empty = none.
  std::vector<double> y_low, y_high;
  // Optional vectors drawn as arrows from (x[i], y[i]) to (x[i] + vector_scale * dx[i],
  // y[i] + vector_scale * dy[i]) (e.g. residuals over the image, magnified); empty = none.
  // A series with vectors draws no line through its points (markers only with `points`).
  std::vector<double> dx, dy;
  double vector_scale = 1.0;
};

// Axes are labelled in the data's own units: with log_y the y axis is logarithmic but its
// ticks read 0.001, 0.01, 0.1 ... (never log10 exponents). The legend sits in its own band
// between the title and the plot area, so it never hides data.
struct Plot {
  std::string title, x_label, y_label;
  std::vector<PlotSeries> series;
  bool log_y = false;  // logarithmic y axis; non-positive values are skipped
  bool y_down = false;       // y grows downwards (image rows), as in an image viewer
  bool equal_scale = false;  // one unit is as long on both axes (images, maps); linear y only
  std::optional<std::pair<double, double>> x_range, y_range;  // fixed axis ranges (e.g. the image size)
  // The SVG document. Non-finite values are skipped.
  std::string ToSvg(int width = 900, int height = 420) const;
  // Written atomically.
  void WriteSvg(const std::filesystem::path& path, int width = 900, int height = 420) const;
};

// Several plots in one SVG document, `columns` per row, each cell_w x cell_h (small
// multiples: e.g. an error against each joint angle). Written atomically.
std::string PlotGridSvg(const std::vector<Plot>& plots, int columns, int cell_w = 450, int cell_h = 300);
void WritePlotGridSvg(const std::filesystem::path& path, const std::vector<Plot>& plots, int columns, int cell_w = 450,
                      int cell_h = 300);

// A heat map of values on a regular grid of cell centres, with a colour bar (viridis)
// labelled with the value's name and unit. Cells without a value (NaN) are grey; with a
// threshold, cells whose value is below it are outlined in red.
struct HeatMap {
  std::string title, x_label, y_label, value_label;
  std::vector<double> x, y;     // cell centres, increasing
  std::vector<double> values;   // values[iy * x.size() + ix]; non-finite = no value
  std::optional<double> vmin, vmax;  // colour range; default: the finite values' range
  bool log_scale = false;       // colours by log10 (positive values only)
  std::optional<double> threshold;
  // The SVG document. std::invalid_argument when the sizes do not match.
  std::string ToSvg(int width = 760, int height = 600) const;
  // Written atomically. std::invalid_argument when the sizes do not match.
  void WriteSvg(const std::filesystem::path& path, int width = 760, int height = 600) const;
};

}  // namespace mcms
