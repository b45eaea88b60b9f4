#include "exid/runner.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <stdio.h>
#include <unistd.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <system_error>
#include <thread>

#include "exid/delay.hpp"
#include "exid/drive.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/input_file.hpp"
#include "exid/inspect.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"
#include "exid/trajectory_export.hpp"
#include "exid/version.hpp"
#include "report.hpp"
#include "run_folder.hpp"
#include "stacked_model.hpp"

namespace exid {

namespace fs = std::filesystem;

namespace {

// The run folder is replaced as a whole when the run is written: an export inside it would be
// lost without a word.
void refuseExportInsideRun(const RunOptions& opt) {
  if (!opt.export_dir.empty()) {
    const fs::path out = fs::weakly_canonical(fs::absolute(opt.out_dir));
    const fs::path exp = fs::weakly_canonical(fs::absolute(opt.export_dir));
    if (std::mismatch(out.begin(), out.end(), exp.begin(), exp.end()).first == out.end())
      throw Error(
          fmt::format("--export {}: inside the output folder {}, which is replaced "
                      "as a whole when the run is written; export to a folder "
                      "outside it",
                      opt.export_dir.string(), opt.out_dir.string()));
  }
  if (!opt.export_dir.empty()) exportFolder(opt.export_dir);  // before any stage runs
}

// summary.json `inputs`: every file the run read through the opener, in path order.
Json inputManifestJson(const InputManifest& m) {
  Json out = Json::array();
  for (const InputRecord& r : m.entries()) {
    Json e = Json::object();
    e["path"] = r.path;
    e["kind"] = r.kind;
    e["size_bytes"] = static_cast<long long>(r.size_bytes);
    e["fnv1a64"] = hashHex(r.fnv1a64);
    out.push_back(std::move(e));
  }
  return out;
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

std::vector<std::string> signalNames(const std::string& prefix, int n) {
  std::vector<std::string> out;
  for (int j = 1; j <= n; ++j) out.push_back(prefix + std::to_string(j));
  return out;
}

// raw: the estimator filters and differentiates the signals itself (EstimatorSpecs::
// needs_raw_dataset), so qd and qdd may be absent.
void checkDataset(const Dataset& d, const RobotModel& robot, const ObservationModel* model,
                  const std::string& what, bool raw = false) {
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
                 const std::vector<std::string>& names = {}) {
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
      {"q", &d.q}, {"qd", &d.qd}, {"qdd", &d.qdd}, {"tau", &d.tau}, {"wrench", &d.wrench}};
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
      sub.source = d.source;
      sub.meta = d.meta;
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
void applyInspection(Json& S, const std::function<void(const std::string&)>& warn, const char* what,
                     const Json& I) {
  if (const Json* w = I.find("warnings"))
    for (std::size_t i = 0; i < w->size(); ++i)
      warn(fmt::format("inspection ({}): {}", what, w->at(i).asString()));
  S["inspection"][what] = I;
}

void inspectInto(Json& S, const std::function<void(const std::string&)>& warn, const char* what,
                 const RobotModel& robot, const ObservationModel* model, const Dataset& d,
                 const RunContext& ctx) {
  applyInspection(S, warn, what, inspectionOf(robot, model, d, ctx));
}

}  // namespace

// (samplesTable, datasetTable: exid/tables.hpp, the data layer)

namespace {

// One study, stage by stage: what the stages share (the study, the summary being built, the
// run's context and folder) and what each leaves to the next (robot, model, trajectory, the
// excitation's optimum, the dataset, the estimate). runStudy() sets up the run folder and the
// watchdog, runs the stages in order and publishes the results; a stage that throws ends the
// study with that stage named.
class StudyRun {
 public:
  StudyRun(const StudyConfig& study, const Registry& registry, const RunOptions& options,
           Json& summary, StudySummary& typed, const fs::path& staging, Report& rep,
           std::function<void(const char*)> set_stage)
      : cfg(study),
        reg(registry),
        opt(options),
        S(summary),
        T(typed),
        write(!options.out_dir.empty()),
        dir(staging),
        report(rep),
        setStage(std::move(set_stage)) {
    ctx.study_dir = cfg.dir;
    ctx.out_dir = dir;
    ctx.seed = cfg.seed;
    ctx.deadline = Deadline(cfg.budget_s);
    ctx.cancelled = opt.cancelled;
  }
  // The inspection beside the estimator reads robot, model and data: it is waited for before
  // they go (also when a stage throws); its result stays.
  ~StudyRun() {
    if (experiment_inspection.valid()) experiment_inspection.wait();
  }
  StudyRun(const StudyRun&) = delete;
  StudyRun& operator=(const StudyRun&) = delete;

  void robotStage();
  void modelStage();
  void excitationStage();
  void experimentStage();
  void identificationStage();
  void validationStage();

  /// What a user should know about this run's results (also logged): the report lists them.
  void warn(const std::string& text) {
    logWarn(text);
    T.warnings.push_back(text);
    S["warnings"].push_back(Json(text));
  }
  /// The experiment's inspection, when it ran beside the estimator, into the summary.
  void collectExperimentInspection() {
    if (experiment_inspection.valid())
      applyInspection(S, warnFn(), "experiment", experiment_inspection.get());
  }

  const StudyConfig& cfg;
  const Registry& reg;
  const RunOptions& opt;
  Json& S;          // summary.json: the typed results (T) rendered, and what has no fixed type
  StudySummary& T;  // the typed results
  const bool write;
  const fs::path dir;  // where this run writes ("" = nowhere)
  Report& report;
  std::function<void(const char*)> setStage;
  RunContext ctx;
  /// Every file the run read through the opener (exid/input_file.hpp): summary.json `inputs`.
  InputManifest manifest;

 private:
  std::function<void(const std::string&)> warnFn() {
    return [this](const std::string& text) { warn(text); };
  }
  void excitationOutputs(const Samples& initial, const Samples& best, const OptimizerResult& r,
                         const ExcitationOptions& xo, Json& X);
  std::function<void(double, const std::string&)> progressFor(const std::string& st) const {
    const RunOptions* o = &opt;
    return [o, st](double f, const std::string& text) {
      if (o->progress) o->progress(st, f, text);
    };
  }

  std::shared_ptr<const RobotModel> robot;
  std::shared_ptr<ObservationModel> model;
  std::shared_ptr<Trajectory> traj;
  std::optional<Samples> reference;  // the excitation's optimum
  Eigen::VectorXd dmin_;             // its smallest distance per design sample (collision)
  std::optional<Dataset> data;
  std::optional<Estimate> est;
  /// The study's estimator, made once from its parameters (its specs steer the experiment, it
  /// identifies, and it processes the validation rows as it processed its own).
  Estimator& estimator() {
    if (!estimator_) estimator_ = reg.create<Estimator>(cfg.estimator->type, cfg.estimator->params);
    return *estimator_;
  }
  std::shared_ptr<Estimator> estimator_;
  // The experiment's inspection when it runs beside the estimator (a recording in memory).
  std::future<Json> experiment_inspection;
};

// The robot: its plugin builds the model of the arm.
void StudyRun::robotStage() {
  setStage("robot");
  const auto t0 = std::chrono::steady_clock::now();
  // Built here even when checkStudy loaded it before the run (opt.robot): the files it reads are
  // the run's inputs (the manifest in summary.json, a matrix cell's key), read by the run.
  robot = reg.create<Robot>(cfg.robot->type, cfg.robot->params)->build(ctx);
  check(robot && robot->dof() > 0, fmt::format("robot '{}' has no joints", cfg.robot->type));
  auto& R = T.robot.emplace();
  R.type = cfg.robot->type;
  R.name = robot->name;
  R.dof = robot->dof();
  R.n_parameters = robot->numInertialParameters();
  R.notes = robot->notes;
  for (const auto& w : robot->warnings) {  // logged on load
    T.warnings.push_back(w);
    S["warnings"].push_back(Json(w));
  }
  R.wall_s = seconds(t0);
  renderInto(R, &S["robot"]);
}

// The observation model, bound to the robot (and to the joints the excitation moves).
void StudyRun::modelStage() {
  if (!cfg.models.empty()) {
    setStage("model");
    const auto t0 = std::chrono::steady_clock::now();
    if (cfg.models.size() == 1) {
      model = reg.create<ObservationModel>(cfg.models[0].type, cfg.models[0].params);
    } else {
      std::vector<std::shared_ptr<ObservationModel>> parts;
      std::vector<double> weights;
      for (const auto& m : cfg.models) {
        parts.push_back(reg.create<ObservationModel>(m.type, m.params));
        weights.push_back(m.weight);
      }
      model = makeStackedModel(std::move(parts), std::move(weights));
    }
    // Joints the excitation trajectory holds still: the base parameters are those the motion
    // of the moving joints can identify (paper section 4, one joint at a time).
    if (cfg.hasExcitation()) {
      traj = reg.create<Trajectory>(cfg.trajectory->type, cfg.trajectory->params);
      traj->bind(robot, ctx);
      std::vector<int> moving = traj->specs().moving_joints;
      if (!moving.empty() && static_cast<int>(moving.size()) < robot->dof()) {
        const Samples s0 = traj->evaluate(traj->initial());
        model->restrictMotion(std::move(moving), s0.q.row(0).transpose());
      }
    }
    if (!cfg.base_columns.empty()) model->preferBaseColumns(cfg.base_columns);
    model->bind(robot, ctx);
    checkFinite(model->fullNominal(),
                fmt::format("model '{}': the robot's nominal parameter", model->pluginName()),
                model->fullNames());
    checkFinite(model->baseNominal(),
                fmt::format("model '{}': the nominal base parameter", model->pluginName()),
                model->base().names);
    T.robot->n_parameters = model->base().numFull();
    T.robot->n_base_parameters = model->numBase();
    renderInto(*T.robot, &S["robot"]);
    Json& Mj = S["model"];
    Mj["type"] = model->pluginName();
    Mj["n_full"] = model->base().numFull();
    Mj["n_base"] = model->numBase();
    Mj["base_parameters"] = Json(model->base().names);
    Mj["details"] = model->describe();
    if (!model->movingJoints().empty()) {  // base parameters of the restricted motion
      std::vector<double> mj;
      for (int j : model->movingJoints()) mj.push_back(j + 1);
      Mj["moving_joints"] = Json(mj);
    }
    Mj["wall_s"] = seconds(t0);
    report.model(*model);
  }
}

// Excitation design: the trajectory that optimises the criterion under the limits.
void StudyRun::excitationStage() {
  if (cfg.hasExcitation()) {
    setStage("excitation");
    if (!traj) {
      traj = reg.create<Trajectory>(cfg.trajectory->type, cfg.trajectory->params);
      traj->bind(robot, ctx);
    }
    auto crit = reg.create<Criterion>(cfg.criterion->type, cfg.criterion->params);
    auto optim = reg.create<Optimizer>(cfg.optimizer->type, cfg.optimizer->params);
    ExcitationOptions xo;
    xo.position_margin = traj->positionMargin();
    xo.velocity_limits = traj->velocityLimits();
    xo.acceleration_limits = traj->accelerationLimits();
    xo.scale_columns = crit->specs().scale_columns;
    xo.torque_margin = cfg.excitation_constraints.getDouble("torque_margin");
    xo.torque_max = cfg.excitation_constraints.getDoubles("torque_max_Nm");
    xo.collision = cfg.excitation_collision;
    Samples initial = traj->evaluate(traj->initial());
    const KnownInformation known = knownInformation(cfg, *model, initial);
    xo.prior_information = known.matrix;
    auto problem = makeExcitationProblem(traj, model, crit, xo);
    RunContext xctx = ctx;
    xctx.progress = progressFor("excitation");
    // A criterion that is NaN (or fails) at the optimiser's answer makes it no answer: the
    // optimisers skip such points, but one that found nothing better may return one (nlopt
    // scores a failed evaluation 1e30). Checked before anything of the stage is written.
    const std::string crit_place = fmt::format(
        "{}{}: excitation.criterion '{}'", cfg.file.empty() ? "study" : cfg.file.string(),
        cfg.criterion->line > 0 ? ":" + std::to_string(cfg.criterion->line) : "",
        cfg.criterion->type);
    auto criterionAt = [&](const Eigen::VectorXd& z, std::string* why) {
      try {
        const double J = problem->value(z, nullptr);
        if (!std::isfinite(J)) *why = fmt::format("it evaluates to {}", J);
        return J;
      } catch (const Error& e) {
        *why = e.what();
        return static_cast<double>(NAN);
      }
    };
    OptimizerResult r;
    try {
      r = optim->minimize(*problem, xctx);
    } catch (const Error& e) {
      std::string why;
      if (ctx.shouldStop() || std::isfinite(criterionAt(traj->initial(), &why))) throw;
      throw Error(fmt::format(
          "{}: no finite value at the initial trajectory ({}) nor at any point optimizer '{}' "
          "tried ({})",
          crit_place, why, cfg.optimizer->type, e.what()));
    }
    if (std::string why; !std::isfinite(criterionAt(r.z, &why))) {
      throw Error(fmt::format(
          "{}: not finite at the trajectory optimizer '{}' returned ({}; {} evaluations, "
          "stop: {}): no usable excitation trajectory",
          crit_place, cfg.optimizer->type, why, r.evaluations, stopReasonText(r)));
    }
    Samples best = traj->evaluate(r.z);
    auto& x = T.excitation.emplace();
    x.trajectory = cfg.trajectory->type;
    x.criterion = cfg.criterion->type;
    x.optimizer = cfg.optimizer->type;
    x.criterion_initial = r.criterion_initial;
    x.criterion_final = r.criterion_final;
    const Eigen::MatrixXd W_initial = model->design(initial), W_best = model->design(best);
    x.cond_W_initial = conditionNumber(W_initial);
    x.cond_W_final = conditionNumber(W_best);
    x.max_constraint_violation = r.max_violation;
    if (xo.torque_margin > 0) {
      // the worst |tau_j| / tau_max,j the full model predicts at the samples
      const Eigen::VectorXd tmax =
          torqueLimits(model->robot(), xo.torque_max, "excitation").tau_max;
      const Eigen::MatrixXd tau = predictedTorques(model->robot(), best);
      x.torque_margin = xo.torque_margin;
      x.torque_ratio_max = (tau.array().abs().rowwise() / tmax.transpose().array()).maxCoeff();
    }
    if (xo.collision) collisionSummary(*xo.collision, model->robot(), initial, best, &x, &dmin_);
    x.feasible = r.feasible;
    if (!r.feasible) warn(infeasibleText(r, x));
    x.iterations = r.iterations;
    x.evaluations = static_cast<long long>(r.evaluations);
    x.wall_s = r.wall_s;
    x.stop_reason = r.stop_reason;
    x.stop_reason_text = stopReasonText(r);
    // A run cut by time gives another answer on another (or a busier) machine.
    x.reproducible = !stoppedByTime(r.stop_reason);
    Json& X = S["excitation"];
    renderInto(x, &X);
    if (known.matrix.size() > 0) {
      // What the design added as known, and the new trajectory's own cond(W) beside the
      // criterion (which saw W^T W + the known information).
      Json& K = X["known_information"];
      K["sources"] = Json(known.sources);
      K["rows_per_design_sample"] = known.rows_per_design_sample;
      auto condTotal = [&](const Eigen::MatrixXd& W) {
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(W.transpose() * W + known.matrix);
        const Eigen::VectorXd l = es.eigenvalues();
        return l(0) > 0 ? std::sqrt(l(l.size() - 1) / l(0)) : INFINITY;
      };
      K["cond_total_initial"] = condTotal(W_initial);
      K["cond_total_final"] = condTotal(W_best);
      K["rule"] =
          "the criterion sees M = W^T W + noise_std^2 / (recording_rate_hz dt) (sum of the known "
          "inverse covariances): the total information up to a factor; cond_W_* are the new "
          "trajectory's alone, cond_total_* sqrt(cond(M))";
    }
    if (!x.reproducible)
      warn(fmt::format(
          "excitation: optimizer '{}' was stopped by a time budget ({}) after {} evaluations: "
          "the trajectory depends on the speed of this machine; for a reproducible result give "
          "an evaluation or iteration budget (max_evaluations, max_iterations)",
          cfg.optimizer->type, stopReasonText(r), r.evaluations));
    X["details"] = r.details;
    X["history"]["t_s"] = Json(r.history_t_s);
    X["history"]["value"] = Json(r.history_value);
    excitationOutputs(initial, best, r, xo, X);
    reference = best;
  }
}

// The excitation's files (trajectories, the criterion's history), its export for execution
// (--export) and its report section.
void StudyRun::excitationOutputs(const Samples& initial, const Samples& best,
                                 const OptimizerResult& r, const ExcitationOptions& xo, Json& X) {
  if (write) {
    writeCsvAtomic(dir / "trajectory_initial.csv", samplesTable(initial));
    writeCsvAtomic(dir / "trajectory_optimal.csv", samplesTable(best));
    CsvTable h;
    h.columns = {"wall_s", "criterion"};
    h.data.resize(static_cast<Eigen::Index>(r.history_value.size()), 2);
    for (std::size_t i = 0; i < r.history_value.size(); ++i) {
      h.data(static_cast<Eigen::Index>(i), 0) = i < r.history_t_s.size() ? r.history_t_s[i] : NAN;
      h.data(static_cast<Eigen::Index>(i), 1) = r.history_value[i];
    }
    writeCsvAtomic(dir / "criterion_history.csv", h);
    X["trajectory_csv"] = "trajectory_optimal.csv";
  }
  if (!opt.export_dir.empty()) {
    TrajectoryExportOptions eo;
    eo.rate_Hz = opt.export_rate_Hz;
    eo.periods = opt.export_periods;
    eo.torque_max = xo.torque_max;
    eo.torque_margin = xo.torque_margin;
    eo.collision = xo.collision;
    eo.plots = cfg.report.plots;
    TrajectoryCheck chk;
    X["export"] = exportTrajectory(*traj, cfg.trajectory->type, cfg.trajectory->params, r.z,
                                   model->robot(), eo, opt.export_dir, &chk);
    X["export"]["dir"] = fs::absolute(opt.export_dir).string();
    if (!chk.ok)
      warn(
          fmt::format("excitation: the exported trajectory ({}) exceeds a limit of the robot "
                      "at {} Hz:\n{}",
                      opt.export_dir.string(), eo.rate_Hz, chk.text()));
  }
  report.excitation(initial, best, r, *model);
  if (xo.torque_margin > 0 || X.find("export")) {
    Eigen::VectorXd tmax;
    Eigen::MatrixXd tau;
    if (xo.torque_margin > 0) {
      tmax = torqueLimits(model->robot(), xo.torque_max, "excitation").tau_max;
      tau = predictedTorques(model->robot(), best);
    }
    report.excitationLimits(best, tau, tmax, xo.torque_margin, X.find("export"));
  }
  if (xo.collision && T.excitation) report.excitationCollision(best, dmin_, *T.excitation);
}

// The experiment: simulated, or a recording read whole or streamed.
void StudyRun::experimentStage() {
  if (cfg.experiment) {
    setStage("experiment");
    const auto t0 = std::chrono::steady_clock::now();
    auto exp = reg.create<Experiment>(cfg.experiment->type, cfg.experiment->params);
    RunContext ectx = ctx;
    ectx.progress = progressFor("experiment");
    const EstimatorSpecs especs = cfg.estimator ? estimator().specs() : EstimatorSpecs();
    // Streamed (read in chunks, never held whole) when the estimator streams and nothing else
    // needs the whole dataset (experiment.csv: always).
    const bool may_stream =
        cfg.estimator && especs.streams && cfg.report.experiment_csv != "always";
    data = may_stream ? exp->stream(robot, reference ? &*reference : nullptr, ectx)
                      : exp->run(robot, reference ? &*reference : nullptr, ectx);
    // A streamed recording that experiment.csv will copy (the `auto` policy: up to
    // kExperimentCsvAutoSamples samples) is read whole once, here: the copy and the estimator
    // then share one pass, and the inspection runs beside the estimator. Streaming pays only
    // when nothing needs the whole recording.
    if (data->streamed() && write && cfg.report.experiment_csv == "auto" &&
        data->size() <= kExperimentCsvAutoSamples)
      data = materialize(*data);
    checkDataset(*data, *robot, model.get(), "experiment", especs.needs_raw_dataset);
    checkDatasetFinite(*data, "experiment");
    auto& ex = T.experiment.emplace();
    ex.type = cfg.experiment->type;
    ex.samples = data->size();
    ex.duration_s = data->tLast() - data->tFirst();
    ex.wall_s = seconds(t0);
    Json& E = S["experiment"];
    renderInto(ex, &E);
    E["meta"] = data->meta;
    if (data->streamed()) {
      E["streamed"] = fmt::format(
          "read from the file in chunks by the estimator '{}' (never held whole); the "
          "recording's statistics and the inspection are from its first pass",
          cfg.estimator->type);
      data->stream->collectEvery(static_cast<int>(streamInspectStride(data->size())));
    }
    for (const std::string& w : experimentWarnings(*data, "experiment")) warn(w);
    if (!data->streamed()) {
      if (cfg.estimator) {
        // The inspection runs beside the estimator (both only read the dataset and the
        // model) and is put into the summary when the estimator is done, at the same place
        // in the summary and among the warnings as if it had run here.
        experiment_inspection = std::async(std::launch::async, [this, ectx] {
          const InputManifestScope inputs(&manifest);  // a file it reads is the run's input
          return inspectionOf(*robot, model.get(), *data, ectx);
        });
      } else {
        inspectInto(S, warnFn(), "experiment", *robot, model.get(), *data, ectx);
      }
    }
    // experiment.csv: simulated data always; recorded data are a copy of the input, written
    // (by default) only while small. What was written, or why not, is in the summary.
    const bool simulated_data =
        data->meta.find("simulated") && data->meta.find("simulated")->asBool();
    const std::string& policy = cfg.report.experiment_csv;
    const bool write_csv =
        policy == "always" ||
        (policy == "auto" && (simulated_data || data->size() <= kExperimentCsvAutoSamples));
    if (write && !write_csv)
      E["csv_not_written"] =
          policy == "never"
              ? std::string("report.params.experiment_csv: never")
              : fmt::format(
                    "recorded data of {} samples (more than {}): a copy of the input; "
                    "report.params.experiment_csv: always writes it",
                    data->size(), kExperimentCsvAutoSamples);
    if (write && write_csv) {
      // The joints named in a first comment line (readers skip it; exid's csv experiment too).
      std::string joints;
      for (int j = 0; j < robot->dof(); ++j) {
        const std::string& jn = robot->hasTransmission()
                                    ? std::string()
                                    : robot->bodies[static_cast<std::size_t>(j)].joint_name;
        joints += fmt::format("{}{} = {}", j ? ", " : "", j + 1,
                              jn.empty() ? fmt::format("measured coordinate {}", j + 1) : jn);
      }
      // written a row at a time: the text is never held whole
      AtomicFileWriter out(dir / "experiment.csv");
      out.write(
          fmt::format("# exid experiment of study '{}', robot '{}': joints {}; SI units, t in s\n",
                      cfg.name, robot->name, joints));
      const Dataset whole = data->streamed() ? materialize(*data) : Dataset();
      writeCsv(out, datasetTable(data->streamed() ? whole : *data));
      out.commit();
      E["csv"] = "experiment.csv";
    }
  }
}

// Identification: the estimator on the dataset; the parameters against the truth or
// the nominal values.
void StudyRun::identificationStage() {
  if (cfg.estimator) {
    setStage("identification");
    const auto t0 = std::chrono::steady_clock::now();
    Estimator& identifier = estimator();
    RunContext ictx = ctx;
    ictx.progress = progressFor("identification");
    std::optional<Prior> prior;
    if (cfg.prior) {
      check(identifier.specs().accepts_prior,
            fmt::format(
                "prior: the estimator '{}' does not take a prior (batch_ls, wls, consistent_ls "
                "and rls do)",
                cfg.estimator->type));
      prior = buildPrior(*cfg.prior, *model);
    }
    est = identifier.estimate(*model, *data, prior ? &*prior : nullptr, ictx);
    collectExperimentInspection();
    if (data->streamed()) {
      // The recording's statistics (and the samples kept for the inspection) are complete
      // after a whole pass: the estimator's, or one more here.
      if (!data->stream->passed()) {
        Dataset chunk;
        data->stream->rewind();
        while (data->stream->read(8192, &chunk) > 0) {
        }
      }
      data->meta = data->stream->meta();
      S["experiment"]["meta"] = data->meta;
      inspectInto(S, warnFn(), "experiment", *robot, model.get(), *data, ictx);
    }
    checkFinite(est->value, fmt::format("estimator '{}': the estimate of", cfg.estimator->type),
                est->names);
    if (est->std.size() > 0)
      checkFinite(est->std,
                  fmt::format("estimator '{}': the standard deviation of", cfg.estimator->type),
                  est->names);
    check(std::isfinite(est->residual_rms),
          fmt::format("estimator '{}': the residual RMS is {} (a non-finite result is an "
                      "error, never a result)",
                      cfg.estimator->type, est->residual_rms));
    auto& id = T.identification.emplace();
    id.estimator = cfg.estimator->type;
    id.wall_s = seconds(t0);
    id.rows = static_cast<long long>(est->rows);
    id.cond_W = est->cond_W;
    id.residual_rms = est->residual_rms;
    id.sigma = est->sigma;
    Json& I = S["identification"];
    I["estimator"] = id.estimator;
    if (cfg.prior) I["prior"] = cfg.resolvedJson()["prior"];
    const bool simulated = data->meta.find("simulated") && data->meta.find("simulated")->asBool();
    const Eigen::VectorXd nominal = model->baseNominal();
    // A simulated study is judged against what the simulation used (its payload), never
    // against a nominal value it did not use.
    const Eigen::VectorXd truth =
        simulated ? Eigen::VectorXd(model->base().reduce(model->fullTruth(data->meta))) : nominal;
    Json params = Json::array();
    double err2 = 0, tru2 = 0;
    for (Eigen::Index i = 0; i < est->value.size(); ++i) {
      Json p = Json::object();
      p["name"] = est->names[static_cast<std::size_t>(i)];
      p["expression"] = est->expressions[static_cast<std::size_t>(i)];
      p["value"] = est->value(i);
      p["std"] = est->std.size() > i ? est->std(i) : NAN;
      p["rel_std_percent"] = est->std.size() > i && est->value(i) != 0
                                 ? 100.0 * est->std(i) / std::abs(est->value(i))
                                 : NAN;
      p["nominal"] = nominal(i);
      if (simulated) p["true"] = truth(i);
      err2 += (est->value(i) - truth(i)) * (est->value(i) - truth(i));
      tru2 += truth(i) * truth(i);
      params.push_back(p);
    }
    if (simulated) {
      id.param_abs_err = std::sqrt(err2);
      if (tru2 > 0)
        id.param_rel_err = std::sqrt(err2 / tru2);
      else
        warn(
            "identification: every true parameter is zero (the simulation used none of the "
            "model's parameters, e.g. no payload): param_rel_err is undefined; "
            "param_abs_err is given");
    }
    renderInto(id, &I);
    I["parameters"] = params;
    if (est->nonlinear.size() > 0) {  // fitted with the linear ones (varpro)
      Json nl = Json::array();
      const std::vector<NonlinearParameter> decl = model->nonlinearParameters();
      for (Eigen::Index k = 0; k < est->nonlinear.size(); ++k) {
        Json p = Json::object();
        const auto u = static_cast<std::size_t>(k);
        p["name"] = u < est->nonlinear_names.size() ? est->nonlinear_names[u] : std::string();
        p["value"] = est->nonlinear(k);
        p["std"] = est->nonlinear_std.size() > k ? est->nonlinear_std(k) : NAN;
        // the model's by name; else the estimator's own (a delay)
        const std::string name = p["name"].asString();
        const auto it = std::find_if(decl.begin(), decl.end(),
                                     [&](const NonlinearParameter& d) { return d.name == name; });
        if (it != decl.end()) {
          p["unit"] = it->unit;
          p["initial"] = it->value;
        } else if (const Json* en = est->details.find("nonlinear_parameters");
                   en && en->isArray() && u < en->size()) {
          if (const Json* v = en->at(u).find("unit")) p["unit"] = *v;
          if (const Json* v = en->at(u).find("initial")) p["initial"] = *v;
        } else if (name == "measurement_delay_s") {
          p["unit"] = "s";
        }
        nl.push_back(p);
      }
      I["nonlinear_parameters"] = nl;
    }
    // the model's nonlinear parameters the estimator did not fit (matched by name)
    {
      std::string names;
      for (const auto& p : model->nonlinearParameters())
        if (std::find(est->nonlinear_names.begin(), est->nonlinear_names.end(), p.name) ==
            est->nonlinear_names.end())
          names +=
              (names.empty() ? "" : ", ") + fmt::format("{} = {:g} {}", p.name, p.value, p.unit);
      if (!names.empty())
        warn(fmt::format(
            "identification: estimator '{}' kept the model's nonlinear parameters at the study's "
            "values ({}); the `varpro` and `didim` estimators fit them",
            cfg.estimator->type, names));
    }
    // Drive gains' columns hold the recorded torque: an estimator other than gains_ls (the
    // torque in the measurement only), iv (a simulated instrument) or didim (the simulated
    // command) has errors in variables there (docs/estimators.md, "gains_ls").
    if (const std::string& et = cfg.estimator->type;
        et != "gains_ls" && et != "iv" && et != "didim") {
      std::string gains, loads;
      for (const std::string& n : est->names) {
        if (torqueColumnKind(n) == 1) gains += (gains.empty() ? "" : ", ") + n;
        if (torqueColumnKind(n) == 2) loads += (loads.empty() ? "" : ", ") + n;
      }
      if (!loads.empty())
        warn(fmt::format(
            "identification: the load-dependent Coulomb columns ({}) hold the recorded torque: "
            "estimator '{}' has errors in variables there, a bias of many standard deviations on "
            "long recordings; gains_ls fits them with the torque in the measurement only",
            loads, cfg.estimator->type));
      if (!gains.empty())
        warn(fmt::format(
            "identification: the drive gains' columns ({}) hold the recorded torque: estimator "
            "'{}' has errors in variables there, which biases the gains towards the recorded "
            "scale (many standard deviations at 1 % torque noise); gains_ls fits them with the "
            "torque in the measurement only",
            gains, cfg.estimator->type));
    }
    I["details"] = est->details;
    if (const Json* w = est->details.find("warnings"); w && w->isArray())
      for (std::size_t i = 0; i < w->size(); ++i) warn("identification: " + w->at(i).asString());
    report.identification(*est, truth, simulated);
  }
}

// The held-out prediction of rows whose columns hold the recorded torque, from the model alone:
// the row tau - p = u - a phi tau (u the other columns' part; dK: a = 1, the column -tau; FcL:
// the column |tau| sign(qdm), a = -sign(tau qdm), p = 0) solved for the torque, tau_hat = (u +
// p) / (1 + a phi) with sign(tau_hat) = sign(u + p); *pred receives tau_hat - p (the rows' y
// units). Returns what was done ("" when the model has no such column).
std::string predictTorqueColumns(const Rows& rows, const Estimate& est, Eigen::VectorXd* pred) {
  std::vector<int> cols, kind;
  for (std::size_t c = 0; c < est.names.size(); ++c)
    if (const int k = torqueColumnKind(est.names[c])) {
      cols.push_back(static_cast<int>(c));
      kind.push_back(k);
    }
  if (cols.empty()) return "";
  for (Eigen::Index i = 0; i < rows.W.rows(); ++i) {
    int c = -1, kd = 0;
    for (std::size_t k = 0; k < cols.size(); ++k)
      if (rows.W(i, cols[k]) != 0.0) {
        c = cols[k];
        kd = kind[k];
      }
    if (c < 0) continue;
    const double w = rows.W(i, c), phi = est.value[c];
    const double u = (*pred)[i] - w * phi;        // the other columns' part
    const double tau = kd == 1 ? -w : rows.y[i];  // the recorded torque
    const double p = tau - rows.y[i];             // the known payload's torque (dK only)
    const double sgn = u + p > 0 ? 1.0 : (u + p < 0 ? -1.0 : 0.0);
    const double a = kd == 1 ? 1.0 : -sgn * (w > 0 ? 1.0 : -1.0);
    (*pred)[i] = (u + p) / (1.0 + a * phi) - p;
  }
  return "the rows with a column of the recorded torque (dK, FcL) are predicted from the model "
         "alone: tau_hat = (w theta + p) / (1 + a phi), not from the recorded torque in their "
         "column";
}

// Validation on held-out data.
void StudyRun::validationStage() {
  if (cfg.validation) {
    setStage("validation");
    const auto t0 = std::chrono::steady_clock::now();
    auto exp = reg.create<Experiment>(cfg.validation->type, cfg.validation->params);
    RunContext vctx = ctx;
    vctx.seed = ctx.seed + 1000003;  // independent noise
    // The validation experiment runs its own trajectory (its own period, harmonics, seed):
    // validating on the identification trajectory (the excitation's optimum) would not
    // measure how the model generalises.
    Dataset vd = exp->run(robot, nullptr, vctx);
    // Raw validation data (no q̇/q̈ yet) for an estimator that processes its own data: its
    // processing makes the validation rows too (the held-out error is then measured on rows
    // processed like the identification rows). Otherwise the model's rows of the data as
    // the validation experiment gives them.
    const Estimator& vest = estimator();
    const bool by_estimator =
        vest.specs().needs_raw_dataset && (!vd.hasVelocity() || !vd.hasAcceleration());
    checkDataset(vd, *robot, model.get(), "validation", by_estimator);
    checkDatasetFinite(vd, "validation");
    // (fitted nonlinear parameters: the held-out rows at the fitted values; the model's own
    // come first in est->nonlinear, then the estimator's, e.g. a delay)
    // (an estimator that does not fit them, e.g. batch_ls, leaves est->nonlinear empty: rows()
    // then uses the study's values)
    // (matched by name: didim with fit_nonlinear: false reports only its delay)
    const std::vector<NonlinearParameter> model_nl = model->nonlinearParameters();
    const auto n_model = static_cast<Eigen::Index>(model_nl.size());
    bool fitted = n_model > 0 && est->nonlinear.size() >= n_model &&
                  static_cast<Eigen::Index>(est->nonlinear_names.size()) >= n_model;
    for (Eigen::Index k = 0; fitted && k < n_model; ++k)
      fitted = est->nonlinear_names[static_cast<std::size_t>(k)] ==
               model_nl[static_cast<std::size_t>(k)].name;
    Rows rows = by_estimator ? vest.validationRows(*model, vd, vctx)
                : fitted     ? model->rowsAt(vd, est->nonlinear.head(n_model), nullptr, vctx)
                             : model->rows(vd, vctx);
    // A fitted measurement delay (varpro): the held-out rows are compensated by it as the fit's
    // were (the model's rows read at t - delay), the samples without them dropped and counted.
    Json delay_meta;
    if (const Json* md = est->details.find("measurement_delay"); md && !by_estimator) {
      const Json* dv = md->find("value_s");
      check(dv && dv->isNumber(), "validation: the estimator's measurement_delay has no value_s");
      const double d = dv->asDouble();
      int front = 0, back = 0;
      const Dataset times = vd.streamed() ? materialize(vd) : Dataset();
      rows = delayedRows(rows, vd.streamed() ? times.t : vd.t, d, "validation", &front, &back);
      delay_meta = Json::object();
      delay_meta["delay_s"] = d;
      delay_meta["samples_without_rows_front"] = front;
      delay_meta["samples_without_rows_back"] = back;
    }
    Eigen::VectorXd pred = rows.W * est->value;
    // Columns that hold the recorded torque itself (drive gains dK, load-dependent Coulomb FcL):
    // W theta would predict the torque from its own measurement. The held-out prediction solves
    // the row for the torque instead (docs/estimators.md, "gains_ls").
    const std::string torque_prediction = predictTorqueColumns(rows, *est, &pred);
    checkFinite(pred, "validation: the predicted measurement, row");
    Eigen::VectorXd err = rows.y - pred;
    auto& va = T.validation.emplace();
    va.type = cfg.validation->type;
    va.samples = vd.size();
    va.rows = static_cast<long long>(rows.y.size());
    Json& V = S["validation"];
    V["type"] = va.type;
    V["samples"] = Json(va.samples);
    V["meta"] = vd.meta;
    if (!delay_meta.isNull()) V["measurement_delay_compensation"] = delay_meta;
    if (!torque_prediction.empty()) V["torque_columns_prediction"] = torque_prediction;
    V["rows_processing"] = by_estimator
                               ? fmt::format(
                                     "the estimator's: '{}' filtered, differentiated and "
                                     "decimated the raw validation data as it did its own",
                                     cfg.estimator->type)
                               : std::string("the model's rows of the validation data as given");
    if (cfg.split) {
      // One recording, two parts: where it was cut, and what each part holds.
      Json sp = Json::object();
      if (cfg.split->identification_fraction > 0)
        sp["identification_fraction"] = cfg.split->identification_fraction;
      else
        sp["at_s"] = cfg.split->at_s;
      if (const Json* m = vd.meta.find("split")) {
        for (const char* k : {"split_at_s", "identification_s", "validation_s"})
          if (const Json* x = m->find(k)) sp[k] = *x;
      }
      sp["identification_samples"] = data->size();
      sp["validation_samples"] = vd.size();
      sp["validation_overrides"] = Json(cfg.split->validation_overrides);
      sp["rule"] =
          "each part is read, filtered, differentiated and trimmed on its own: no sample of "
          "one part enters the other";
      S["split"] = sp;
    }
    for (const std::string& w : experimentWarnings(vd, "validation")) warn(w);
    inspectInto(S, warnFn(), "validation", *robot, model.get(), vd, vctx);
    va.relative_error = rows.y.norm() > 0 ? err.norm() / rows.y.norm() : NAN;
    va.residual_rms =
        rows.y.size() > 0 ? err.norm() / std::sqrt(static_cast<double>(rows.y.size())) : NAN;
    std::vector<double> rms(static_cast<std::size_t>(rows.numEquations), 0.0), cnt(rms.size(), 0.0),
        ref(rms.size(), 0.0);
    for (Eigen::Index r = 0; r < rows.y.size(); ++r) {
      const auto e = static_cast<std::size_t>(
          rows.equation.empty() ? 0 : rows.equation[static_cast<std::size_t>(r)]);
      rms[e] += err(r) * err(r);
      ref[e] += rows.y(r) * rows.y(r);
      cnt[e] += 1;
    }
    std::vector<double> relj(rms.size());
    for (std::size_t e = 0; e < rms.size(); ++e) {
      relj[e] = ref[e] > 0 ? std::sqrt(rms[e] / ref[e]) : NAN;
      rms[e] = cnt[e] > 0 ? std::sqrt(rms[e] / cnt[e]) : NAN;
    }
    va.rms_per_joint = rms;
    va.relative_error_per_joint = relj;
    va.wall_s = seconds(t0);
    renderInto(va, &V);
    if (!rows.equation_names.empty()) V["equations"] = Json(rows.equation_names);
    if (write) {
      // t of each row's sample so rows can be matched with other tools; the equations named
      // in a comment line.
      CsvTable t;
      t.columns = {"t", "row", "equation", "measured", "predicted"};
      t.data.resize(rows.y.size(), 5);
      const bool has_t = rows.t.size() == static_cast<std::size_t>(rows.y.size());
      for (Eigen::Index r = 0; r < rows.y.size(); ++r) {
        t.data(r, 0) = has_t ? rows.t[static_cast<std::size_t>(r)] : NAN;
        t.data(r, 1) = static_cast<double>(r);
        t.data(r, 2) = rows.equation.empty() ? 0 : rows.equation[static_cast<std::size_t>(r)];
        t.data(r, 3) = rows.y(r);
        t.data(r, 4) = pred(r);
      }
      std::string names;
      for (std::size_t e = 0; e < rows.equation_names.size(); ++e)
        names += fmt::format("{}{} = {}", e ? ", " : "", e, rows.equation_names[e]);
      writeFileAtomic(dir / "validation.csv",
                      fmt::format("# exid validation of study '{}': equation {}\n{}", cfg.name,
                                  names.empty() ? std::string("indices") : names, toCsv(t)));
    }
    report.validation(rows, pred, va);
  }
}

}  // namespace

namespace {
// A study's result before its stages: status "running", the build, the configuration's hash.
StudyResult startedResult(const StudyConfig& cfg) {
  StudyResult res;
  Json& S = res.summary;
  res.headline.study = cfg.name;
  S = Json::object();
  renderInto(res.headline, &S);  // status "running", message, study, warnings
  S["exid_version"] = EXID_VERSION_STRING;
  S["exid_commit"] = gitCommit();
  S["build"] = Registry::fingerprintText();
  S["config_hash"] = cfg.hash();
  S["seed"] = Json(static_cast<long long>(cfg.seed));
  return res;
}
}  // namespace

StudyResult runStudy(const StudyConfig& cfg, const Registry& reg, const RunOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  StudyResult res = startedResult(cfg);
  Json& S = res.summary;
  StudySummary& T = res.headline;
  const bool write = !opt.out_dir.empty();
  RunFolder folder;
  if (write) {
    try {
      refuseExportInsideRun(opt);
      folder = prepareRunFolder(opt.out_dir, opt.clean_stale);
    } catch (const std::exception& e) {  // nothing written, nothing replaced
      res.ok = false;
      res.message = fmt::format("stage 'setup': {}", e.what());
      T.status = "failed";
      T.failed_stage = "setup";
      T.message = res.message;
      renderInto(T, &S);
      return res;
    }
  }
  const fs::path dir = folder.staging;  // where this run writes ("" = nowhere)
  Report report(cfg, dir);
  std::string stage = "setup";
  std::atomic<const char*> stage_now{"setup"};  // for the watchdog's thread
  auto setStage = [&](const char* name) {
    stage = name;
    stage_now = name;
  };
  Watchdog watchdog(opt, write ? folder : RunFolder{}, cfg, stage_now, t_start);
  StudyRun run(cfg, reg, opt, S, T, dir, report, setStage);
  const RunContext& ctx = run.ctx;
  std::optional<InputManifestScope> inputs;  // files the stages read: the run's manifest
  inputs.emplace(&run.manifest);
  try {
    if (write) {
      writeFileAtomic(dir / "study.resolved.yaml", cfg.resolvedYaml());
    }
    run.robotStage();
    run.modelStage();
    run.excitationStage();
    run.experimentStage();
    run.identificationStage();
    run.validationStage();
    if (ctx.shouldStop())
      throw Error(fmt::format("stopped: {}",
                              ctx.deadline.expired() ? "study budget_s exhausted" : "interrupted"));
    T.status = "ok";
    renderInto(T, &S);
    judgeResults(S, &T);  // the results' own verdict, from what the stages wrote
    res.ok = true;
  } catch (const std::exception& e) {
    run.collectExperimentInspection();  // (a failed identification keeps the data's inspection)
    res.ok = false;
    const auto* io = dynamic_cast<const IoError*>(&e);
    const bool nomem = dynamic_cast<const std::bad_alloc*>(&e) != nullptr;
    res.message = fmt::format("stage '{}': {}", stage,
                              nomem ? std::string("out of memory (std::bad_alloc)") : e.what());
    res.cancelled = opt.cancelled && opt.cancelled();
    T.status = res.cancelled ? "cancelled" : "failed";
    T.failed_stage = stage;
    T.message = res.message;
    if (io && io->outOfSpace()) S["out_of_space"] = true;  // the machine's, not the study's
    // (a thread or mapping refused under a memory cap: std::system_error EAGAIN / ENOMEM)
    const auto* se = dynamic_cast<const std::system_error*>(&e);
    if (nomem || (se && (se->code() == std::errc::resource_unavailable_try_again ||
                         se->code() == std::errc::not_enough_memory)))
      S["out_of_memory"] = true;
    if (ctx.deadline.expired()) S["timed_out"] = true;  // over budget_s: a timeout, not a bug
  }
  inputs.reset();
  S["inputs"] = inputManifestJson(run.manifest);
  T.wall_s = seconds(t_start);
  renderInto(T, &S);
  const std::lock_guard<std::mutex> finishing(watchdog.finishing());
  watchdog.finished();
  if (write) {
    // Published where: a failure beside an earlier successful run goes to NAME.failed.
    const bool beside = !res.ok && holdsOkRun(folder.final_dir);
    const fs::path target = beside ? folder.failed_dir : folder.final_dir;
    try {
      if (res.ok) {
        const std::string missing = report.write(T);
        S["report"] = (folder.final_dir / "report.md").string();
        if (!missing.empty()) S["report_missing_plots"] = missing;
      }
      if (beside)
        S["note"] = fmt::format(
            "this run failed; the results of the earlier successful run in {} are untouched",
            folder.final_dir.string());
      writeFileAtomic(dir / "summary.json", S.dump(2) + "\n");
      std::error_code ec;
      if (res.ok || !beside) fs::remove_all(folder.failed_dir, ec);  // superseded
      publish(dir, target);
      res.written_to = target == folder.final_dir ? folder.named : target;
    } catch (const std::exception& e) {
      res.ok = false;
      const auto* io = dynamic_cast<const IoError*>(&e);
      if (io && io->outOfSpace()) S["out_of_space"] = true;
      res.message +=
          (res.message.empty() ? "" : "; ") + std::string("writing results: ") + e.what();
      T.status = "failed";
      T.message = res.message;
      renderInto(T, &S);
      // Whatever was written stays in the staging folder's place only if publishing it
      // worked; the earlier results are never touched. Try to leave the failure visible.
      std::error_code ec;
      try {
        writeFileAtomic(dir / "summary.json", S.dump(2) + "\n");
        const bool besides2 = holdsOkRun(folder.final_dir);
        const fs::path t2 = besides2 ? folder.failed_dir : folder.final_dir;
        if (fs::exists(dir, ec)) {
          if (besides2) fs::remove_all(folder.failed_dir, ec);
          publish(dir, t2);
          res.written_to = t2 == folder.final_dir ? folder.named : t2;
        }
      } catch (const std::exception&) {
        fs::remove_all(dir, ec);  // nothing half written is left behind
      }
    }
  }
  return res;
}

StudyConfig stageStudy(StudyConfig cfg, const std::string& stage, const Registry& reg,
                       const fs::path& data) {
  const std::string study = cfg.file.empty() ? cfg.name : cfg.file.string();
  if (!data.empty() && stage != "identify")
    throw Error(
        fmt::format("a data file replaces the experiment of stage 'identify' alone (stage "
                    "'{}')",
                    stage));
  if (stage == "excite") {
    if (!cfg.hasExcitation()) throw Error(fmt::format("{}: no excitation section", study));
    cfg.experiment.reset();
    cfg.estimator.reset();
    cfg.validation.reset();
  } else if (stage == "simulate") {
    if (!cfg.experiment) throw Error(fmt::format("{}: no experiment section", study));
    cfg.estimator.reset();
    cfg.validation.reset();
  } else if (stage == "identify") {
    if (!cfg.estimator) throw Error(fmt::format("{}: no estimator section", study));
    cfg.trajectory.reset();
    cfg.criterion.reset();
    cfg.optimizer.reset();
    cfg.validation.reset();
    if (!data.empty()) {
      // A ROS 2 bag is a folder holding metadata.yaml (experiment rosbag2, parameter `path`);
      // anything else is a CSV file (experiment csv, parameter `file`).
      const bool bag = fs::is_directory(data) && fs::exists(data / "metadata.yaml");
      const char* type = bag ? "rosbag2" : "csv";
      std::string esc;
      for (char ch : fs::absolute(data).string())
        esc += ch == '\'' ? std::string("''") : std::string(1, ch);
      PluginSpec spec;
      spec.kind = PluginKind::Experiment;
      spec.type = type;
      spec.key_path = "experiment";
      spec.params = resolveParams(reg.get(PluginKind::Experiment, type),
                                  fmt::format("{{{}: '{}'}}", bag ? "path" : "file", esc),
                                  "experiment.params", fs::current_path());
      cfg.experiment = spec;
    }
    if (!cfg.experiment)
      throw Error(fmt::format("{}: no experiment section and no data file", study));
  } else {
    throw Error(fmt::format("unknown stage '{}'; stages: excite, simulate, identify", stage));
  }
  return cfg;
}

}  // namespace exid
