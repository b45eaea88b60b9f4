// exid — plots for reports, drawn by gnuplot (run as a process) as SVG and PNG. Every plot's
// data is also written as CSV, whether or not gnuplot is available.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace exid {

struct PlotSeries {
  std::string title;
  std::vector<double> x, y;
  std::string style = "lines";        // lines | points | linespoints | boxes | band
  std::vector<double> y_low, y_high;  // style "band": filled band between them (y unused)
};

struct PlotSpec {
  std::string name;  // file stem: plots/<name>.{csv,svg,png}
  std::string title, xlabel, ylabel;
  std::vector<PlotSeries> series;
  bool log_y = false;
};

struct PlotOutcome {
  std::string csv, svg, png;  // paths relative to the report folder ("" when not written)
  std::string missing_why;    // why the pictures are missing ("" when drawn)
};

/// The gnuplot program to use ("" when none is installed). EXID_GNUPLOT overrides the search
/// ("none" disables plotting).
std::string gnuplotProgram();

/// Writes dir/plots/<name>.csv and, when gnuplot is available, .svg and .png (atomically).
PlotOutcome drawPlot(const PlotSpec& spec, const std::filesystem::path& dir);

}  // namespace exid
