// exid — several observation models stacked into one (stacked_model.hpp).
#include "stacked_model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <string>

#include "exid/error.hpp"

namespace exid {

namespace {

class StackedModel final : public ObservationModel {
 public:
  StackedModel(std::vector<std::shared_ptr<ObservationModel>> parts, std::vector<double> weights)
      : parts_(std::move(parts)), weights_(std::move(weights)) {
    setPluginName("stack");
  }
  std::vector<std::string> fullNames() const override { return names_; }
  Eigen::VectorXd fullNominal() const override {
    Eigen::VectorXd v = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(names_.size()));
    for (std::size_t m = 0; m < parts_.size(); ++m) {
      Eigen::VectorXd nm = parts_[m]->fullNominal();
      for (std::size_t c = 0; c < map_[m].size(); ++c)
        v(map_[m][c]) = nm(static_cast<Eigen::Index>(c));
    }
    return v;
  }
  Eigen::VectorXd fullTruth(const PlantTruth& plant) const override {
    Eigen::VectorXd v = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(names_.size()));
    for (std::size_t m = 0; m < parts_.size(); ++m) {
      Eigen::VectorXd tm = parts_[m]->fullTruth(plant);
      for (std::size_t c = 0; c < map_[m].size(); ++c)
        v(map_[m][c]) = tm(static_cast<Eigen::Index>(c));
    }
    return v;
  }
  Rows fullRows(const Dataset& data, const RunContext& ctx) const override {
    std::vector<Rows> blocks;
    Eigen::Index rows = 0;
    for (const auto& p : parts_) {
      blocks.push_back(p->fullRows(data, ctx));
      rows += blocks.back().W.rows();
    }
    Rows out;
    out.W = Eigen::MatrixXd::Zero(rows, static_cast<Eigen::Index>(names_.size()));
    out.y.resize(rows);
    Eigen::Index r0 = 0;
    int eq0 = 0;
    for (std::size_t m = 0; m < blocks.size(); ++m) {
      const Rows& b = blocks[m];
      for (std::size_t c = 0; c < map_[m].size(); ++c)
        out.W.block(r0, map_[m][c], b.W.rows(), 1) =
            weights_[m] * b.W.col(static_cast<Eigen::Index>(c));
      out.y.segment(r0, b.y.size()) = weights_[m] * b.y;
      for (int e : b.equation) out.equation.push_back(eq0 + e);
      if (b.t.size() == static_cast<std::size_t>(b.y.size()))
        out.t.insert(out.t.end(), b.t.begin(), b.t.end());
      else
        out.t.insert(out.t.end(), static_cast<std::size_t>(b.y.size()), NAN);
      for (int e = 0; e < b.numEquations; ++e)
        out.equation_names.push_back(parts_[m]->pluginName() + ": " +
                                     (e < static_cast<int>(b.equation_names.size())
                                          ? b.equation_names[static_cast<std::size_t>(e)]
                                          : fmt::format("equation {}", e)));
      eq0 += b.numEquations;
      r0 += b.W.rows();
    }
    out.numEquations = eq0;
    return out;
  }
  Eigen::MatrixXd fullDesign(const Samples& s) const override {
    std::vector<Eigen::MatrixXd> blocks;
    Eigen::Index rows = 0;
    for (const auto& p : parts_) {
      blocks.push_back(p->fullDesign(s));
      rows += blocks.back().rows();
    }
    Eigen::MatrixXd W = Eigen::MatrixXd::Zero(rows, static_cast<Eigen::Index>(names_.size()));
    Eigen::Index r0 = 0;
    for (std::size_t m = 0; m < blocks.size(); ++m) {
      for (std::size_t c = 0; c < map_[m].size(); ++c)
        W.block(r0, map_[m][c], blocks[m].rows(), 1) =
            weights_[m] * blocks[m].col(static_cast<Eigen::Index>(c));
      r0 += blocks[m].rows();
    }
    return W;
  }
  void fullDesignVjp(const Samples& s, const Eigen::MatrixXd& dW, Samples* grad) const override {
    grad->t = s.t;
    grad->q = Eigen::MatrixXd::Zero(s.q.rows(), s.q.cols());
    grad->qd = grad->q;
    grad->qdd = grad->q;
    Eigen::Index r0 = 0;
    for (std::size_t m = 0; m < parts_.size(); ++m) {
      const Eigen::Index rows = rowsPerDesign_[m] * s.size();
      Eigen::MatrixXd sub(rows, static_cast<Eigen::Index>(map_[m].size()));
      for (std::size_t c = 0; c < map_[m].size(); ++c)
        sub.col(static_cast<Eigen::Index>(c)) = weights_[m] * dW.block(r0, map_[m][c], rows, 1);
      Samples g;
      parts_[m]->fullDesignVjp(s, sub, &g);
      grad->q += g.q;
      grad->qd += g.qd;
      grad->qdd += g.qdd;
      r0 += rows;
    }
  }
  // Every part's signals. Not declared per sample: the stack's rows are computed on the whole
  // dataset at once, as they always were.
  ModelSpecs specs() const override {
    ModelSpecs sp;
    sp.required_signals.clear();
    for (const auto& p : parts_)
      for (const auto& s : p->specs().required_signals)
        if (std::find(sp.required_signals.begin(), sp.required_signals.end(), s) ==
            sp.required_signals.end())
          sp.required_signals.push_back(s);
    return sp;
  }
  Json describe() const override {
    Json j = Json::array();
    for (std::size_t m = 0; m < parts_.size(); ++m) {
      Json p = Json::object();
      p["type"] = parts_[m]->pluginName();
      p["weight"] = weights_[m];
      p["details"] = parts_[m]->describe();
      j.push_back(p);
    }
    return j;
  }

 protected:
  void onBind(const RunContext& ctx) override {
    names_.clear();
    map_.clear();
    rowsPerDesign_.clear();
    Samples probe = randomSamples(1, ctx.seed);
    for (const auto& p : parts_) {
      if (!movingJoints().empty()) p->restrictMotion(movingJoints(), heldPositions());
      p->bind(robotPtr(), ctx);
      std::vector<int> idx;
      for (const auto& n : p->fullNames()) {
        auto it = std::find(names_.begin(), names_.end(), n);
        if (it == names_.end()) {
          names_.push_back(n);
          idx.push_back(static_cast<int>(names_.size()) - 1);
        } else {
          idx.push_back(static_cast<int>(it - names_.begin()));
        }
      }
      map_.push_back(idx);
      rowsPerDesign_.push_back(static_cast<int>(p->fullDesign(probe).rows()));
    }
  }

 private:
  std::vector<std::shared_ptr<ObservationModel>> parts_;
  std::vector<double> weights_;
  std::vector<std::string> names_;
  std::vector<std::vector<int>> map_;
  std::vector<int> rowsPerDesign_;
};

}  // namespace

std::shared_ptr<ObservationModel> makeStackedModel(
    std::vector<std::shared_ptr<ObservationModel>> parts, std::vector<double> weights) {
  return std::make_shared<StackedModel>(std::move(parts), std::move(weights));
}

}  // namespace exid
