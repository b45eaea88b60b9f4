// exid — what a study's stages share (stages.hpp): their environment, where their records go,
// the inspection of a dataset, the checks of what they read and make.
#include "stages.hpp"

namespace exid {

StageEnv::StageEnv(const StudyConfig& study, const Registry& registry, const RunOptions& options,
                   fs::path staging, std::function<void(const char*)> stage)
    : cfg(study),
      reg(registry),
      opt(options),
      dir(std::move(staging)),
      set_stage(std::move(stage)) {
  ctx.study_dir = cfg.dir;
  ctx.out_dir = dir;
  ctx.seed = cfg.seed;
  ctx.deadline = Deadline(cfg.budget_s);
  ctx.cancelled = opt.cancelled;
}

std::function<void(double, const std::string&)> StageEnv::progressFor(
    const std::string& stage) const {
  const RunOptions* o = &opt;
  return [o, stage](double f, const std::string& text) {
    if (o->progress) o->progress(stage, f, text);
  };
}

void StudyRecord::warn(const std::string& text, bool log) {
  if (log) logWarn(text);
  typed->warnings.push_back(text);
  (*summary)["warnings"].push_back(Json(text));
}

// What a study says when the optimiser found no trajectory within every constraint.
std::string infeasibleText(const OptimizerResult& r, const StudySummary::Excitation& x) {
  std::string s = fmt::format(
      "excitation: no feasible trajectory found: the result violates the constraints by up to "
      "{:.4g} (stop: {})",
      r.max_violation, stopReasonText(r));
  if (x.distance_margin_m && x.min_distance_final_m &&
      *x.min_distance_final_m < *x.distance_margin_m)
    s += fmt::format(
        "; the pair {} comes within {:.4g} m (margin {:.4g} m): if the two cannot collide by "
        "construction, list them in excitation.collision.allowed_pairs, or lower margin_m",
        x.min_distance_pair, *x.min_distance_final_m, *x.distance_margin_m);
  if (x.torque_ratio_max && x.torque_margin && *x.torque_ratio_max > *x.torque_margin)
    s += fmt::format("; the predicted torque reaches {:.4g} of its limit (margin {:.4g})",
                     *x.torque_ratio_max, *x.torque_margin);
  return s;
}

// The smallest distance over the design samples and checked pairs, initial and final.
void collisionSummary(const CollisionOptions& o, const RobotModel& robot, const Samples& initial,
                      const Samples& best, StudySummary::Excitation* x,
                      Eigen::VectorXd* dmin_best) {
  CollisionModel cm(robot, o);
  // Per pair, the smallest distance over the samples; per sample, the smallest over the pairs.
  auto sweep = [&](const Samples& s, Eigen::VectorXd* per_pair, Eigen::VectorXd* per_sample) {
    per_pair->setConstant(cm.numPairs(), HUGE_VAL);
    per_sample->resize(s.size());
    Eigen::VectorXd d;
    for (int k = 0; k < s.size(); ++k) {
      cm.distances(s.q.row(k).transpose(), &d);
      *per_pair = per_pair->cwiseMin(d);
      (*per_sample)(k) = d.minCoeff();
    }
  };
  Eigen::VectorXd per_pair, per_sample;
  x->distance_margin_m = o.margin_m;
  x->collision_pairs = cm.numPairs();
  x->collision_excluded = cm.excludedPairs();
  sweep(initial, &per_pair, &per_sample);
  x->min_distance_initial_m = per_pair.minCoeff();
  sweep(best, &per_pair, dmin_best);
  Eigen::Index closest = 0;
  x->min_distance_final_m = per_pair.minCoeff(&closest);
  x->min_distance_pair = cm.pairNames()[static_cast<std::size_t>(closest)];
  std::vector<int> order(static_cast<std::size_t>(cm.numPairs()));
  for (int i = 0; i < cm.numPairs(); ++i) order[static_cast<std::size_t>(i)] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return per_pair(a) < per_pair(b); });
  for (std::size_t i = 0; i < order.size() && i < 5; ++i)
    x->closest_pairs_m.emplace_back(cm.pairNames()[static_cast<std::size_t>(order[i])],
                                    per_pair(order[i]));
}

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// (the stacked model: stacked_model.hpp; the run folder and the watchdog: run_folder.hpp)

// raw: the estimator filters and differentiates the signals itself (EstimatorSpecs::
// needs_raw_dataset), so qd and qdd may be absent.
void checkDataset(const Dataset& d, const RobotModel& robot, const ObservationModel* model,
                  const std::string& what, bool raw) {
  check(d.size() > 0, fmt::format("{} ({}): no samples", what, d.source));
  check((d.streamed() || d.q.rows() == d.size()) && d.dof() == robot.dof(),
        fmt::format("{} ({}): q has {} columns, the robot '{}' has {} joints", what, d.source,
                    d.dof(), robot.name, robot.dof()));
  // (a stream checks its time stamps when it opens)
  for (int k = 1; k < (d.streamed() ? 0 : d.size()); ++k)
    check(d.t(k) > d.t(k - 1),
          fmt::format("{} ({}): time must increase; row {} has t = {} after {}", what, d.source,
                      k + 1, d.t(k), d.t(k - 1)));
  if (!model) return;
  for (const auto& sig : model->specs().required_signals) {
    if (raw && (sig == "qd" || sig == "qdd")) continue;
    bool present = sig == "q" || (sig == "qd" && d.hasVelocity()) ||
                   (sig == "qdd" && d.hasAcceleration()) || (sig == "tau" && d.hasTorque()) ||
                   (sig == "wrench" && d.hasWrench());
    check(present, fmt::format("{} ({}): the model '{}' needs the signal '{}', which the data "
                               "lacks (columns {}1..{}{})",
                               what, d.source, model->pluginName(), sig, sig, sig,
                               sig == "wrench" ? "6" : std::to_string(robot.dof())));
  }
}

// Every value finite, else an error naming the stage's quantity, the element and the value.
void checkFinite(const Eigen::MatrixXd& M, const std::string& what,
                 const std::vector<std::string>& names) {
  for (Eigen::Index j = 0; j < M.cols(); ++j)
    for (Eigen::Index i = 0; i < M.rows(); ++i)
      if (!std::isfinite(M(i, j))) {
        std::string where = M.cols() == 1
                                ? (static_cast<std::size_t>(i) < names.size()
                                       ? fmt::format("'{}'", names[static_cast<std::size_t>(i)])
                                       : fmt::format("element {}", i + 1))
                                : fmt::format("row {}, column {}", i + 1, j + 1);
        throw Error(fmt::format("{}: {} is {} (a non-finite result is an error, never a result)",
                                what, where, M(i, j)));
      }
}

// (a streamed dataset: every value is checked by the stream as it is read)
void checkDatasetFinite(const Dataset& d, const std::string& what) {
  if (d.streamed()) return;
  const std::pair<const char*, const Eigen::MatrixXd*> sig[] = {
      {"q", &d.q},           {"qd", &d.qd},     {"qdd", &d.qdd},        {"tau", &d.tau},
      {"wrench", &d.wrench}, {"base", &d.base}, {"contact", &d.contact}};
  checkFinite(d.t, fmt::format("{} ({}): t", what, d.source));
  for (const auto& [name, M] : sig)
    if (M->size() > 0) checkFinite(*M, fmt::format("{} ({}): {}", what, d.source, name));
}

// A long recording is inspected on every s-th sample (at most kRunInspectSamples): the checks
// cost a fraction of the identification, never several times it. `exid inspect` looks at every
// sample.
constexpr long kRunInspectSamples = 100000;
// Of those, the regressor's condition number (the costliest check: the model's rows again, which
// the estimator builds itself) uses every s-th, at most this many. The estimator reports its own
// condition number over every row (identification.cond_W).
constexpr long kRunRegressorSamples = 20000;
long streamInspectStride(long K) { return (K + kRunInspectSamples - 1) / kRunInspectSamples; }

// exid inspect's checks on a dataset of the study (inspect.hpp): the whole result under
// summary.json `inspection.<what>`, its warnings among the study's. An inspection that cannot be
// done is noted there; it never fails the study.
// The inspection's result for a dataset: the checks, or a note when it could not be done.
Json inspectionOf(const RobotModel& robot, const ObservationModel* model, const Dataset& d,
                  const RunContext& ctx) {
  try {
    const long K = d.size();
    Json I;
    if (d.streamed()) {  // the samples the stream kept on its first pass (streamInspectStride)
      const long stride = streamInspectStride(K);
      check(d.stream->passed(), "inspection: the stream has not been read");
      Dataset sub = d.stream->collected();
      sub.meta = d.meta;
      sub.facts = d.facts;
      I = inspectDataset(robot, model, sub, ctx, kRunRegressorSamples);
      if (stride > 1)
        I["subsampled"] = fmt::format(
            "every {}th of the {} samples ({} inspected; `exid inspect` looks at every sample)",
            stride, K, sub.size());
    } else if (K > kRunInspectSamples) {
      const long stride = (K + kRunInspectSamples - 1) / kRunInspectSamples;
      Dataset sub;
      const long M = (K + stride - 1) / stride;
      auto take = [&](const Eigen::MatrixXd& A) {
        if (A.size() == 0) return Eigen::MatrixXd();
        Eigen::MatrixXd B(M, A.cols());
        for (long i = 0; i < M; ++i) B.row(i) = A.row(i * stride);
        return B;
      };
      sub.t.resize(M);
      for (long i = 0; i < M; ++i) sub.t(i) = d.t(i * stride);
      sub.q = take(d.q);
      sub.qd = take(d.qd);
      sub.qdd = take(d.qdd);
      sub.tau = take(d.tau);
      sub.wrench = take(d.wrench);
      sub.base = take(d.base);
      sub.contact = take(d.contact);
      sub.source = d.source;
      sub.meta = d.meta;
      sub.facts = d.facts;
      I = inspectDataset(robot, model, sub, ctx, kRunRegressorSamples);
      I["subsampled"] = fmt::format(
          "every {}th of the {} samples ({} inspected; `exid inspect` looks at every sample)",
          stride, K, M);
    } else {
      I = inspectDataset(robot, model, d, ctx, kRunRegressorSamples);
    }
    return I;
  } catch (const std::exception& e) {
    Json I = Json::object();
    I["note"] = fmt::format("not inspected: {}", e.what());
    return I;
  }
}

// An inspection's result under summary.json `inspection.<what>`, its warnings among the study's.
void applyInspection(StudyRecord& rec, const char* what, const Json& I) {
  if (const Json* w = I.find("warnings"))
    for (std::size_t i = 0; i < w->size(); ++i)
      rec.warn(fmt::format("inspection ({}): {}", what, w->at(i).asString()));
  (*rec.summary)["inspection"][what] = I;
}

void record(const ExperimentFollowUp& f, StudyRecord& rec) {
  if (f.meta) (*rec.summary)["experiment"]["meta"] = *f.meta;
  if (f.inspection) applyInspection(rec, "experiment", *f.inspection);
}

}  // namespace exid
