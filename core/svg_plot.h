// Minimal SVG line/scatter plots for reports (no plotting library on the dependency
// list does this in C++; the files open in any browser).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace mcms {

struct PlotSeries {
  std::string label;
  std::vector<double> x, y;
  std::string color = "#1f77b4";
  bool points = false;  // markers instead of a line
};

struct Plot {
  std::string title, x_label, y_label;
  std::vector<PlotSeries> series;
  // Written atomically. Non-finite values are skipped.
  void WriteSvg(const std::filesystem::path& path, int width = 900, int height = 420) const;
};

}  // namespace mcms
