// The figures a person reads a study by (framework/plot/src/figures.hpp): the validation plot's
// data against time with the residual, and the torque limits drawn inside the plot's range.
#include "figures.hpp"  // framework/plot/src

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "exid/io.hpp"

namespace fs = std::filesystem;

namespace {

// Two equations interleaved (as a model's rows are), time in seconds from 0.5 s at 100 Hz.
exid::Rows twoEquations(Eigen::VectorXd* predicted) {
  exid::Rows r;
  const int K = 50;
  r.numEquations = 2;
  r.y.resize(2 * K);
  predicted->resize(2 * K);
  for (int k = 0; k < K; ++k)
    for (int e = 0; e < 2; ++e) {
      const int i = 2 * k + e;
      const double t = 0.5 + 0.01 * k;
      r.t.push_back(t);
      r.equation.push_back(e);
      r.y(i) = std::sin(3.0 * t + e) * (e + 1) * 10.0;
      (*predicted)(i) = r.y(i) + 0.1 * std::cos(7.0 * t + e);
    }
  r.equation_names = {"tau1 shoulder [N m or N]", "tau2 elbow [N m or N]"};
  return r;
}

}  // namespace

TEST(Figures, ValidationDataHasTimeInSecondsAndTheResidual) {
  Eigen::VectorXd pred;
  const exid::Rows rows = twoEquations(&pred);
  const exid::PlotSpec spec = exid::validationPlot(rows, pred, 1);
  EXPECT_EQ(spec.name, "validation_equation2");
  EXPECT_EQ(spec.xlabel, "t [s]");
  EXPECT_NE(spec.title.find("tau2 elbow"), std::string::npos) << spec.title;
  // the data file drawPlot writes (the same with or without gnuplot)
  const fs::path dir = fs::temp_directory_path() / ("exid_figures_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  ASSERT_EQ(::setenv("EXID_GNUPLOT", "none", 1), 0);
  const exid::PlotOutcome o = exid::drawPlot(spec, dir);
  ::unsetenv("EXID_GNUPLOT");
  ASSERT_EQ(o.csv, "plots/validation_equation2.csv");
  const exid::CsvTable T = exid::readCsv(dir / o.csv);
  ASSERT_EQ(T.columns, (std::vector<std::string>{"t_s", "measured", "predicted", "residual"}));
  ASSERT_EQ(T.data.rows(), 50);
  Eigen::Index k = 0;
  for (Eigen::Index i = 0; i < rows.y.size(); ++i) {
    if (rows.equation[static_cast<std::size_t>(i)] != 1) continue;
    EXPECT_EQ(T.data(k, 0), rows.t[static_cast<std::size_t>(i)]) << "row " << k;
    EXPECT_EQ(T.data(k, 1), rows.y(i));
    EXPECT_EQ(T.data(k, 2), pred(i));
    EXPECT_EQ(T.data(k, 3), T.data(k, 1) - T.data(k, 2)) << "residual = measured - predicted";
    ++k;
  }
  // measured underneath (thick, light), predicted on top (thin), the residual in a panel below
  ASSERT_EQ(spec.series.size(), 3u);
  EXPECT_GT(spec.series[0].width, spec.series[1].width);
  EXPECT_NE(spec.series[0].color, spec.series[1].color);
  EXPECT_EQ(spec.series[2].panel, 1);
  const std::string g = exid::plotScript(spec, "d.csv", "svg", "o.svg");
  EXPECT_NE(g.find("set multiplot"), std::string::npos) << g;
  EXPECT_LT(g.find("title \"measured\""), g.find("title \"predicted\"")) << "measured first";
  fs::remove_all(dir);
}

TEST(Figures, ValidationWithoutTimeCountsSamples) {
  Eigen::VectorXd pred;
  exid::Rows rows = twoEquations(&pred);
  rows.t.clear();
  rows.equation_names.clear();
  const exid::PlotSpec spec = exid::validationPlot(rows, pred, 0);
  EXPECT_EQ(spec.xlabel, "sample");
  const std::string csv = exid::plotCsv(spec);
  EXPECT_EQ(csv.substr(0, csv.find('\n')), "sample,measured,predicted,residual");
}

TEST(Figures, TorqueLimitsLieInsideThePlotRange) {
  const int K = 101;
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(K, 0.0, 10.0);
  Eigen::MatrixXd tau(K, 2);
  for (int k = 0; k < K; ++k) {
    tau(k, 0) = 40.0 * std::sin(t(k));  // within 0.46 of 87
    tau(k, 1) = 5.0 * std::cos(t(k));   // within 0.42 of 12
  }
  const Eigen::Vector2d tau_max(87.0, 12.0);
  for (double margin : {0.0, 0.8}) {
    const exid::PlotSpec p = exid::torqueRatioPlot("torque_ratio", "torque", t, tau, tau_max,
                                                   margin, {"shoulder", "elbow"});
    ASSERT_EQ(p.limits.size(), margin > 0 ? 4u : 2u);
    const exid::PlotRange r = exid::plotYRange(p);
    EXPECT_LT(r.low, -1.0) << "the range must strictly contain -limit, with headroom";
    EXPECT_GT(r.high, 1.0);
    EXPECT_LT(r.low, -1.05);
    EXPECT_GT(r.high, 1.05);
    EXPECT_EQ(p.series[0].title, "tau1 (shoulder)");
    const std::string g = exid::plotScript(p, "d.csv", "svg", "o.svg");
    EXPECT_NE(g.find("set yrange ["), std::string::npos) << g;
    EXPECT_NE(g.find("nohead dt 2"), std::string::npos) << "limits dashed: " << g;
    EXPECT_NE(g.find("set label \"+tau_max\""), std::string::npos) << "limits labelled: " << g;
  }
  // a torque beyond its limit stays inside the range too
  tau(50, 1) = -18.0;  // 1.5 tau_max
  const exid::PlotRange r =
      exid::plotYRange(exid::torqueRatioPlot("t", "t", t, tau, tau_max, 0.8, {}));
  EXPECT_LT(r.low, -1.5);
  EXPECT_GT(r.high, 1.0);
}
