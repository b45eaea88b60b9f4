// exid — the study-level prior (StudyConfig::prior) on a model's base parameters.
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/interfaces.hpp"
#include "exid/runner.hpp"

namespace exid {

namespace {

std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> out;
  std::string cell;
  std::stringstream ss(line);
  while (std::getline(ss, cell, ',')) {
    while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
    while (!cell.empty() && cell.front() == ' ') cell.erase(cell.begin());
    out.push_back(cell);
  }
  return out;
}

}  // namespace

Prior buildPrior(const PriorSpec& spec, const ObservationModel& model) {
  const BaseParameters& b = model.base();
  const int p = b.rank();
  Prior prior;
  if (spec.from == "robot") {
    const Eigen::VectorXd pi0 = model.fullNominal();
    const std::vector<std::string> names = model.fullNames();
    Eigen::VectorXd sd(pi0.size());
    for (Eigen::Index i = 0; i < pi0.size(); ++i) {
      const bool drive = isDriveParameterName(names[static_cast<std::size_t>(i)]);
      const double rel =
          drive ? spec.drive_relative_std.value_or(spec.relative_std) : spec.relative_std;
      const double abs =
          drive ? spec.drive_absolute_std.value_or(spec.absolute_std) : spec.absolute_std;
      sd(i) = std::hypot(rel * pi0(i), abs);
    }
    prior.value = b.K * pi0;
    prior.covariance = b.K * sd.cwiseAbs2().asDiagonal() * b.K.transpose();
    prior.standard_value = pi0;
    prior.standard_std = sd;
    Eigen::LLT<Eigen::MatrixXd> llt(prior.covariance);
    if (llt.info() != Eigen::Success || !(prior.covariance.diagonal().minCoeff() > 0)) {
      std::string zero;
      for (int i = 0; i < p; ++i)
        if (!(prior.covariance(i, i) > 0))
          zero += (zero.empty() ? "" : ", ") + b.names[static_cast<std::size_t>(i)];
      throw Error(fmt::format(
          "prior (from: robot): the prior covariance of the base parameters is not positive "
          "definite (zero variance: {}); the robot's nominal values of these are zero, "
          "give prior.absolute_std > 0",
          zero.empty() ? "none" : zero));
    }
    return prior;
  }
  // from: study -- parameters.csv of an earlier study (name, value, std by base parameter)
  const auto file = spec.study / "parameters.csv";
  std::string text;
  try {
    text = readInputFile(file, "prior parameters", kMaxDataFileBytes);
  } catch (const Error& e) {
    throw Error(
        fmt::format("prior (from: study): {} (the output folder of a study with an "
                    "estimator)",
                    e.what()));
  }
  std::istringstream in(text);
  std::string line;
  check(static_cast<bool>(std::getline(in, line)), fmt::format("{}: empty file", file.string()));
  const auto head = splitCsvLine(line);
  auto col = [&](const char* n) {
    for (std::size_t i = 0; i < head.size(); ++i)
      if (head[i] == n) return static_cast<int>(i);
    throw Error(fmt::format("{}: no column '{}' (expected name, value, std)", file.string(), n));
  };
  const int cn = col("name"), cv = col("value"), cs = col("std");
  std::map<std::string, std::pair<double, double>> rows;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line == "\r") continue;
    const auto c = splitCsvLine(line);
    check(static_cast<int>(c.size()) > std::max({cn, cv, cs}),
          fmt::format("{}:{}: expected {} columns", file.string(), lineno, head.size()));
    double v = NAN, s = NAN;
    try {
      v = std::stod(c[static_cast<std::size_t>(cv)]);
      s = std::stod(c[static_cast<std::size_t>(cs)]);
    } catch (const std::exception&) {
      throw Error(fmt::format("{}:{}: value and std must be numbers", file.string(), lineno));
    }
    rows[c[static_cast<std::size_t>(cn)]] = {v, s};
  }
  prior.value.resize(p);
  Eigen::VectorXd sd(p);
  for (int i = 0; i < p; ++i) {
    const std::string& n = b.names[static_cast<std::size_t>(i)];
    auto it = rows.find(n);
    check(it != rows.end(),
          fmt::format("prior (from: study): {} has no base parameter '{}' (the studies must "
                      "share the robot and the observation model)",
                      file.string(), n));
    check(
        std::isfinite(it->second.first) && std::isfinite(it->second.second) &&
            it->second.second > 0,
        fmt::format("prior (from: study): {}: '{}' needs a finite value and a positive finite std "
                    "(found {} and {})",
                    file.string(), n, it->second.first, it->second.second));
    prior.value(i) = it->second.first;
    sd(i) = spec.scale * it->second.second;
  }
  prior.covariance = sd.cwiseAbs2().asDiagonal();
  return prior;
}

}  // namespace exid
