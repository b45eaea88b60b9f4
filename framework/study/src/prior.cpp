// exid — the study-level prior (StudyConfig::prior) on a model's base parameters.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "exid/base_parameters.hpp"
#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/interfaces.hpp"
#include "exid/runner.hpp"
#include "exid/study_check.hpp"

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

struct PriorRow {
  double value = 0.0, std = 0.0;
  int line = 0;
};

/// parameters.csv of an earlier study (PriorSpec::from == "study"): name -> value, std, line;
/// every row checked (a finite value, a positive std whose variance is usable).
std::map<std::string, PriorRow> readPriorRows(const PriorSpec& spec) {
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
  std::map<std::string, PriorRow> rows;
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
    const std::string& name = c[static_cast<std::size_t>(cn)];
    check(std::isfinite(v) && std::isfinite(s) && s > 0,
          fmt::format("prior (from: study): {}:{}: '{}' needs a finite value and a positive "
                      "finite std (found {} and {})",
                      file.string(), lineno, name, v, s));
    check(spec.scale * s <= kMaxPriorStd,
          fmt::format("prior (from: study): {}:{}: '{}' has std {:g}{}, more than {:g}: too "
                      "large to be used as a prior (its variance overflows or swamps every "
                      "other); a std this large says nothing: give a smaller one",
                      file.string(), lineno, name, s,
                      spec.scale != 1.0 ? fmt::format(" (x scale {:g})", spec.scale) : "",
                      kMaxPriorStd));
    rows[name] = PriorRow{v, s, lineno};
  }
  return rows;
}

}  // namespace

void checkPriorFile(const PriorSpec& spec) { readPriorRows(spec); }

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
      // (a std of 1e300 squares to infinity: the covariance below would be NaN, not "zero")
      check(sd(i) <= kMaxPriorStd,
            fmt::format(
                "prior (from: robot): the std of '{}' is {:g} (relative_std {:g} x |{:g}|, "
                "absolute_std {:g}), more than {:g}: too large to be used as a prior "
                "(its variance overflows); a std this large says nothing: give a "
                "smaller {}",
                names[static_cast<std::size_t>(i)], sd(i), rel, pi0(i), abs, kMaxPriorStd,
                drive ? "drive_relative_std / drive_absolute_std" : "relative_std / absolute_std"));
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
  const std::map<std::string, PriorRow> rows = readPriorRows(spec);
  prior.value.resize(p);
  Eigen::VectorXd sd(p);
  for (int i = 0; i < p; ++i) {
    const std::string& n = b.names[static_cast<std::size_t>(i)];
    auto it = rows.find(n);
    check(it != rows.end(),
          fmt::format("prior (from: study): {} has no base parameter '{}' (the studies must "
                      "share the robot and the observation model)",
                      file.string(), n));
    prior.value(i) = it->second.value;
    sd(i) = spec.scale * it->second.std;
  }
  prior.covariance = sd.cwiseAbs2().asDiagonal();
  return prior;
}

namespace {

/// The inverse of a symmetric positive definite covariance; `what` names it in the error.
Eigen::MatrixXd informationOf(const Eigen::MatrixXd& cov, const std::string& what) {
  Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (cov + cov.transpose()));
  check(llt.info() == Eigen::Success && cov.allFinite(),
        fmt::format("{}: the covariance is not positive definite (a base parameter the earlier "
                    "data did not determine); its information cannot be added",
                    what));
  return llt.solve(Eigen::MatrixXd::Identity(cov.rows(), cov.cols()));
}

/// covariance.csv of an earlier study, reordered to the model's base parameters.
Eigen::MatrixXd readCovariance(const std::filesystem::path& dir, const BaseParameters& b) {
  const auto file = dir / "covariance.csv";
  std::string text;
  try {
    text = readInputFile(file, "covariance", kMaxDataFileBytes);
  } catch (const Error& e) {
    throw Error(
        fmt::format("excitation.information.earlier_study: {} (the output folder of a "
                    "study whose identification succeeded)",
                    e.what()));
  }
  std::istringstream in(text);
  std::string line;
  check(static_cast<bool>(std::getline(in, line)), fmt::format("{}: empty file", file.string()));
  auto head = splitCsvLine(line);
  check(!head.empty() && head[0] == "name",
        fmt::format("{}:1: expected the header name,<base parameters>", file.string()));
  head.erase(head.begin());
  const auto m = static_cast<Eigen::Index>(head.size());
  Eigen::MatrixXd C(m, m);
  std::vector<std::string> rows;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line == "\r") continue;
    const auto c = splitCsvLine(line);
    const auto r = static_cast<Eigen::Index>(rows.size());
    check(r < m && static_cast<Eigen::Index>(c.size()) == m + 1,
          fmt::format("{}:{}: expected {} rows of a name and {} numbers", file.string(), lineno, m,
                      m));
    rows.push_back(c[0]);
    for (Eigen::Index j = 0; j < m; ++j) {
      try {
        std::size_t used = 0;
        const std::string& cell = c[static_cast<std::size_t>(j + 1)];
        C(r, j) = std::stod(cell, &used);
        check(used == cell.size(), "");
      } catch (const std::exception&) {
        throw Error(
            fmt::format("{}:{}: column {}: expected a number", file.string(), lineno, j + 2));
      }
    }
  }
  check(static_cast<Eigen::Index>(rows.size()) == m && rows == head,
        fmt::format("{}: expected a square table whose rows are named like its columns",
                    file.string()));
  const int p = b.rank();
  Eigen::MatrixXd out(p, p);
  std::vector<Eigen::Index> at(static_cast<std::size_t>(p));
  for (int i = 0; i < p; ++i) {
    const std::string& n = b.names[static_cast<std::size_t>(i)];
    const auto it = std::find(head.begin(), head.end(), n);
    check(it != head.end(),
          fmt::format("excitation.information.earlier_study: {} has no base parameter '{}' (the "
                      "studies must share the robot, the observation model and base_columns)",
                      file.string(), n));
    at[static_cast<std::size_t>(i)] = it - head.begin();
  }
  check(m == p, fmt::format("excitation.information.earlier_study: {} has {} base parameters, "
                            "the model {} (the studies must share the robot, the observation "
                            "model and base_columns)",
                            file.string(), m, p));
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j)
      out(i, j) = C(at[static_cast<std::size_t>(i)], at[static_cast<std::size_t>(j)]);
  return out;
}

}  // namespace

KnownInformation knownInformation(const StudyConfig& cfg, const ObservationModel& model,
                                  const Samples& design) {
  KnownInformation k;
  if (!cfg.hasExcitationInformation()) return k;
  const ParamSet& P = cfg.excitation_information;
  const double sigma = P.getDouble("noise_std"), rate = P.getDouble("recording_rate_hz");
  check(sigma > 0 && rate > 0,
        "excitation.information: noise_std and recording_rate_hz are required with an earlier "
        "study or a prior");
  // The design's sample period: each design sample stands for rate * dt recorded samples.
  check(design.size() >= 2, "excitation.information: the trajectory has fewer than 2 samples");
  const double dt = (design.t(design.size() - 1) - design.t(0)) / (design.size() - 1);
  check(dt > 0, "excitation.information: the trajectory's time does not increase");
  k.rows_per_design_sample = rate * dt;
  const int p = model.numBase();
  Eigen::MatrixXd I = Eigen::MatrixXd::Zero(p, p);  // information, 1 / parameter units^2
  const std::string earlier = P.getString("earlier_study");
  if (!earlier.empty()) {
    I += informationOf(
        readCovariance(earlier, model.base()),
        fmt::format("excitation.information.earlier_study: {}/covariance.csv", earlier));
    k.sources.push_back(
        fmt::format("earlier study {} (the inverse of its covariance.csv)", earlier));
  }
  const double rel = P.getDouble("prior_relative_std"), abs = P.getDouble("prior_absolute_std");
  if (rel > 0 || abs > 0) {
    PriorSpec spec;
    spec.from = "robot";
    spec.relative_std = rel;
    spec.absolute_std = abs;
    const Prior prior = buildPrior(spec, model);
    I += informationOf(prior.covariance, "excitation.information: the prior");
    k.sources.push_back(fmt::format(
        "the robot description's values, std = {} |value| + {} per standard parameter", rel, abs));
  }
  // The new experiment's information is (rate dt / sigma^2) W^T W over the design's samples:
  // the criterion sees M = W^T W + sigma^2 / (rate dt) I, the same matrix up to a factor.
  k.matrix = (sigma * sigma / k.rows_per_design_sample) * I;
  return k;
}

}  // namespace exid
