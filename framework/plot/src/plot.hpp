// exid — plots for reports, drawn by gnuplot (run as a process) as SVG and PNG. Every plot's
// data is also written as CSV, whether or not gnuplot is available.
#pragma once

#include <cmath>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace exid {

struct PlotSeries {
  std::string title;
  std::vector<double> x, y;
  std::string style = "lines";        // lines | points | linespoints | boxes | band
  std::vector<double> y_low, y_high;  // style "band": filled band between them (y unused)
  std::string color;                  // "#rrggbb" ("": gnuplot's next colour)
  double width = 0.0;                 // line width (0: gnuplot's)
  int panel = 0;                      // 0: the main panel; 1: the panel below it (residuals)
};

/// A series of style (lines, points, linespoints, boxes) in gnuplot's colours.
inline PlotSeries plotLine(std::string title, std::vector<double> x, std::vector<double> y,
                           std::string style = "lines") {
  PlotSeries s;
  s.title = std::move(title);
  s.x = std::move(x);
  s.y = std::move(y);
  s.style = std::move(style);
  return s;
}

/// A filled band between low and high.
inline PlotSeries plotBand(std::string title, std::vector<double> x, std::vector<double> low,
                           std::vector<double> high) {
  PlotSeries s;
  s.title = std::move(title);
  s.x = std::move(x);
  s.style = "band";
  s.y_low = std::move(low);
  s.y_high = std::move(high);
  return s;
}

/// A horizontal line drawn as a limit: dashed, labelled, inside the plot's y range.
struct PlotLimit {
  double y = 0.0;
  std::string label;
  std::string color = "#c0392b";
};

struct PlotSpec {
  std::string name;  // file stem: plots/<name>.{csv,svg,png}
  std::string title, xlabel, ylabel;
  std::vector<PlotSeries> series;
  bool log_y = false;
  /// Limits as dashed labelled lines; with any, the main panel's y range holds the data and
  /// every limit with headroom (plotYRange), so that no limit lies on the frame.
  std::vector<PlotLimit> limits;
  /// Series in panel 1 make a second panel below the main one, sharing its x axis (multiplot).
  std::string lower_ylabel;
  /// Non-empty, and every series sharing the same x: the CSV is one x column of this name and
  /// one column per series named by its title (e.g. t_s, measured, predicted, residual).
  std::string x_column;
};

struct PlotRange {
  double low = NAN, high = NAN;  // NaN: gnuplot's own (autoscale)
};

/// The main panel's y range: with limits, the span of the data and of every limit, widened by
/// 8 % of it on each side (a flat span: by 1 or 10 % of the value); otherwise autoscale.
PlotRange plotYRange(const PlotSpec& spec);

struct PlotOutcome {
  std::string csv, svg, png;  // paths relative to the report folder ("" when not written)
  std::string missing_why;    // why the pictures are missing ("" when drawn)
};

/// The gnuplot program to use ("" when none is installed). EXID_GNUPLOT overrides the search
/// ("none" disables plotting).
std::string gnuplotProgram();

/// The CSV drawPlot writes for spec (the header line, then one line per row).
std::string plotCsv(const PlotSpec& spec);

/// The gnuplot script that draws spec from its CSV (csv) on terminal into output.
std::string plotScript(const PlotSpec& spec, const std::string& csv, const std::string& terminal,
                       const std::string& output);

/// Writes dir/plots/<name>.csv and, when gnuplot is available, .svg and .png (atomically).
PlotOutcome drawPlot(const PlotSpec& spec, const std::filesystem::path& dir);

}  // namespace exid
