// exid — a study's robot, model and excitation stages and their records (stages.hpp).
#include "stages.hpp"

namespace exid {

RobotStageOut robotStage(const StageEnv& env) {
  const StudyConfig& cfg = env.cfg;
  env.enter("robot");
  const auto t0 = std::chrono::steady_clock::now();
  RobotStageOut out;
  // Built here even when checkStudy loaded it before the run (opt.robot): the files it reads are
  // the run's inputs (the manifest in summary.json, a matrix cell's key), read by the run.
  out.robot = env.reg.create<Robot>(cfg.robot->type, cfg.robot->params)->build(env.ctx);
  const RobotModel* robot = out.robot.get();
  check(robot && robot->dof() > 0, fmt::format("robot '{}' has no joints", cfg.robot->type));
  RobotSummary& R = out.summary;
  R.type = cfg.robot->type;
  R.name = robot->name;
  R.dof = robot->dof();
  R.n_parameters = robot->numInertialParameters();
  R.notes = robot->notes;
  out.warnings = robot->warnings;
  R.wall_s = seconds(t0);
  return out;
}

void record(const StageEnv&, const RobotStageOut& r, StudyRecord& rec) {
  StudySummary& T = *rec.typed;
  T.robot = r.summary;
  for (const auto& w : r.warnings) rec.warn(w, false);  // logged on load
  renderInto(*T.robot, &(*rec.summary)["robot"]);
}

ModelStageOut modelStage(const StageEnv& env, const RobotStageOut& robot_out) {
  const StudyConfig& cfg = env.cfg;
  ModelStageOut out;
  if (cfg.models.empty()) return out;
  env.enter("model");
  const auto t0 = std::chrono::steady_clock::now();
  const std::shared_ptr<const RobotModel>& robot = robot_out.robot;
  std::shared_ptr<ObservationModel>& model = out.model;
  if (cfg.models.size() == 1) {
    model = env.reg.create<ObservationModel>(cfg.models[0].type, cfg.models[0].params);
  } else {
    std::vector<std::shared_ptr<ObservationModel>> parts;
    std::vector<double> weights;
    for (const auto& m : cfg.models) {
      parts.push_back(env.reg.create<ObservationModel>(m.type, m.params));
      weights.push_back(m.weight);
    }
    model = makeStackedModel(std::move(parts), std::move(weights));
  }
  // Joints the excitation trajectory holds still: the base parameters are those the motion
  // of the moving joints can identify (paper section 4, one joint at a time).
  if (cfg.hasExcitation()) {
    out.traj = env.reg.create<Trajectory>(cfg.trajectory->type, cfg.trajectory->params);
    out.traj->bind(robot, env.ctx);
    std::vector<int> moving = out.traj->specs().moving_joints;
    if (!moving.empty() && static_cast<int>(moving.size()) < robot->dof()) {
      const Samples s0 = out.traj->evaluate(out.traj->initial());
      model->restrictMotion(std::move(moving), s0.q.row(0).transpose());
    }
  }
  if (!cfg.base_columns.empty()) model->preferBaseColumns(cfg.base_columns);
  if (cfg.base_columns_pivoted) model->baseColumnRule(BaseParameterOptions::Rule::Pivoted);
  model->bind(robot, env.ctx);
  checkFinite(model->fullNominal(),
              fmt::format("model '{}': the robot's nominal parameter", model->pluginName()),
              model->fullNames());
  checkFinite(model->baseNominal(),
              fmt::format("model '{}': the nominal base parameter", model->pluginName()),
              model->base().names);
  out.type = model->pluginName();
  out.n_full = model->base().numFull();
  out.n_base = model->numBase();
  out.base_parameters = model->base().names;
  out.details = model->describe();
  for (int j : model->movingJoints()) out.moving_joints.push_back(j + 1);
  out.wall_s = seconds(t0);
  return out;
}

void record(const StageEnv&, const ModelStageOut& m, StudyRecord& rec) {
  if (!m.model) return;
  StudySummary& T = *rec.typed;
  Json& S = *rec.summary;
  T.robot->n_parameters = m.n_full;
  T.robot->n_base_parameters = m.n_base;
  renderInto(*T.robot, &S["robot"]);
  Json& Mj = S["model"];
  Mj["type"] = m.type;
  Mj["n_full"] = m.n_full;
  Mj["n_base"] = m.n_base;
  Mj["base_parameters"] = Json(m.base_parameters);
  Mj["details"] = m.details;
  if (!m.moving_joints.empty())  // base parameters of the restricted motion
    Mj["moving_joints"] = Json(m.moving_joints);
  Mj["wall_s"] = m.wall_s;
  if (rec.report) rec.report->model(*m.model);
}

namespace {

// The excitation's options: the trajectory's limits, the criterion's scaling, the study's torque
// limits and collision avoidance.
ExcitationOptions excitationOptions(const StudyConfig& cfg, const Trajectory& traj,
                                    const Criterion& crit) {
  ExcitationOptions xo;
  xo.position_margin = traj.positionMargin();
  xo.velocity_limits = traj.velocityLimits();
  xo.acceleration_limits = traj.accelerationLimits();
  xo.scale_columns = crit.specs().scale_columns;
  xo.torque_margin = cfg.excitation_constraints.getDouble("torque_margin");
  xo.torque_max = cfg.excitation_constraints.getDoubles("torque_max_Nm");
  xo.collision = cfg.excitation_collision;
  return xo;
}

// The optimiser's answer: a criterion that is NaN (or fails) at it makes it no answer. The
// optimisers skip such points, but one that found nothing better may return one (nlopt scores
// a failed evaluation 1e30). Checked before anything of the stage is recorded.
OptimizerResult optimise(const StageEnv& env, Optimizer& optim, ExcitationProblem& problem,
                         const Trajectory& traj) {
  const StudyConfig& cfg = env.cfg;
  RunContext xctx = env.ctx;
  xctx.progress = env.progressFor("excitation");
  const std::string crit_place =
      fmt::format("{}{}: excitation.criterion '{}'", cfg.file.empty() ? "study" : cfg.file.string(),
                  cfg.criterion->line > 0 ? ":" + std::to_string(cfg.criterion->line) : "",
                  cfg.criterion->type);
  auto criterionAt = [&](const Eigen::VectorXd& z, std::string* why) {
    try {
      const double J = problem.value(z, nullptr);
      if (!std::isfinite(J)) *why = fmt::format("it evaluates to {}", J);
      return J;
    } catch (const Error& e) {
      *why = e.what();
      return static_cast<double>(NAN);
    }
  };
  OptimizerResult r;
  try {
    r = optim.minimize(problem, xctx);
  } catch (const Error& e) {
    std::string why;
    if (env.ctx.shouldStop() || std::isfinite(criterionAt(traj.initial(), &why))) throw;
    throw Error(fmt::format(
        "{}: no finite value at the initial trajectory ({}) nor at any point optimizer '{}' "
        "tried ({})",
        crit_place, why, cfg.optimizer->type, e.what()));
  }
  if (std::string why; !std::isfinite(criterionAt(r.z, &why))) {
    throw Error(
        fmt::format("{}: not finite at the trajectory optimizer '{}' returned ({}; {} evaluations, "
                    "stop: {}): no usable excitation trajectory",
                    crit_place, cfg.optimizer->type, why, r.evaluations, stopReasonText(r)));
  }
  return r;
}

// What the design added as known, and the new trajectory's own cond(W) beside the criterion
// (which saw W^T W + the known information).
Json knownInformationJson(const KnownInformation& known, const Eigen::MatrixXd& W_initial,
                          const Eigen::MatrixXd& W_best) {
  Json K = Json::object();
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
  return K;
}

}  // namespace

ExcitationStageOut excitationStage(const StageEnv& env, const RobotStageOut& robot,
                                   const ModelStageOut& model_out) {
  const StudyConfig& cfg = env.cfg;
  ExcitationStageOut out;
  if (!cfg.hasExcitation()) return out;
  env.enter("excitation");
  out.ran = true;
  out.model = model_out.model;
  const std::shared_ptr<ObservationModel>& model = out.model;
  out.traj = model_out.traj;
  if (!out.traj) {
    out.traj = env.reg.create<Trajectory>(cfg.trajectory->type, cfg.trajectory->params);
    out.traj->bind(robot.robot, env.ctx);
  }
  const std::shared_ptr<Trajectory>& traj = out.traj;
  auto crit = env.reg.create<Criterion>(cfg.criterion->type, cfg.criterion->params);
  auto optim = env.reg.create<Optimizer>(cfg.optimizer->type, cfg.optimizer->params);
  ExcitationOptions& xo = out.options = excitationOptions(cfg, *traj, *crit);
  out.initial = traj->evaluate(traj->initial());
  const KnownInformation known = knownInformation(cfg, *model, out.initial);
  xo.prior_information = known.matrix;
  auto problem = makeExcitationProblem(traj, model, crit, xo);
  const OptimizerResult& r = out.result = optimise(env, *optim, *problem, *traj);
  out.best = traj->evaluate(r.z);
  ExcitationSummary& x = out.summary;
  x.trajectory = cfg.trajectory->type;
  x.criterion = cfg.criterion->type;
  x.optimizer = cfg.optimizer->type;
  x.criterion_initial = r.criterion_initial;
  x.criterion_final = r.criterion_final;
  const Eigen::MatrixXd W_initial = model->design(out.initial), W_best = model->design(out.best);
  x.cond_W_initial = conditionNumber(W_initial);
  x.cond_W_final = conditionNumber(W_best);
  x.max_constraint_violation = r.max_violation;
  if (xo.torque_margin > 0) {
    // the worst |tau_j| / tau_max,j the full model predicts at the samples
    out.tau_max = torqueLimits(model->robot(), xo.torque_max, "excitation").tau_max;
    out.tau = predictedTorques(model->robot(), out.best);
    x.torque_margin = xo.torque_margin;
    x.torque_ratio_max =
        (out.tau.array().abs().rowwise() / out.tau_max.transpose().array()).maxCoeff();
  }
  if (xo.collision)
    collisionSummary(*xo.collision, model->robot(), out.initial, out.best, &x, &out.min_distance);
  x.feasible = r.feasible;
  if (!r.feasible) out.warnings.push_back(infeasibleText(r, x));
  x.iterations = r.iterations;
  x.evaluations = static_cast<long long>(r.evaluations);
  x.wall_s = r.wall_s;
  x.stop_reason = r.stop_reason;
  x.stop_reason_text = stopReasonText(r);
  // A run cut by time gives another answer on another (or a busier) machine.
  x.reproducible = !stoppedByTime(r.stop_reason);
  if (r.stop_reason == StopReason::NoProgress)
    out.warnings.push_back(fmt::format(
        "excitation: optimizer '{}' made no progress: it stopped at its start ({} -> {}) after "
        "{} evaluations, its first search direction not descending; the designed trajectory is "
        "the initial one (try objective: log, other starts or another algorithm)",
        cfg.optimizer->type, r.criterion_initial, r.criterion_final, r.evaluations));
  if (known.matrix.size() > 0)
    out.known_information = knownInformationJson(known, W_initial, W_best);
  if (!x.reproducible)
    out.warnings.push_back(fmt::format(
        "excitation: optimizer '{}' was stopped by a time budget ({}) after {} evaluations: "
        "the trajectory depends on the speed of this machine; for a reproducible result give "
        "an evaluation or iteration budget (max_evaluations, max_iterations)",
        cfg.optimizer->type, stopReasonText(r), r.evaluations));
  return out;
}

namespace {

// The excitation's files: the initial and the optimal trajectory, the criterion's history.
void writeExcitationFiles(const fs::path& dir, const ExcitationStageOut& x) {
  writeCsvAtomic(dir / "trajectory_initial.csv", samplesTable(x.initial));
  writeCsvAtomic(dir / "trajectory_optimal.csv", samplesTable(x.best));
  const OptimizerResult& r = x.result;
  CsvTable h;
  h.columns = {"wall_s", "criterion"};
  h.data.resize(static_cast<Eigen::Index>(r.history_value.size()), 2);
  for (std::size_t i = 0; i < r.history_value.size(); ++i) {
    h.data(static_cast<Eigen::Index>(i), 0) = i < r.history_t_s.size() ? r.history_t_s[i] : NAN;
    h.data(static_cast<Eigen::Index>(i), 1) = r.history_value[i];
  }
  writeCsvAtomic(dir / "criterion_history.csv", h);
}

// The optimal trajectory exported for execution (--export): summary.json excitation.export.
Json exportExcitation(const StageEnv& env, const ExcitationStageOut& x, StudyRecord& rec) {
  const RunOptions& opt = env.opt;
  TrajectoryExportOptions eo;
  eo.rate_Hz = opt.export_rate_Hz;
  eo.periods = opt.export_periods;
  eo.torque_max = x.options.torque_max;
  eo.torque_margin = x.options.torque_margin;
  eo.collision = x.options.collision;
  eo.plots = env.cfg.report.plots;
  TrajectoryCheck chk;
  const auto progress = env.progressFor("export");
  progress(0.0, fmt::format("sampling at {} Hz and checking every limit", eo.rate_Hz));
  Json E = exportTrajectory(*x.traj, env.cfg.trajectory->type, env.cfg.trajectory->params,
                            x.result.z, x.model->robot(), eo, opt.export_dir, &chk);
  progress(1.0, chk.ok ? "every limit holds" : "a limit is exceeded");
  E["dir"] = fs::absolute(opt.export_dir).string();
  if (!chk.ok)
    rec.warn(
        fmt::format("excitation: the exported trajectory ({}) exceeds a limit of the robot "
                    "at {} Hz:\n{}",
                    opt.export_dir.string(), eo.rate_Hz, chk.text()));
  if (!chk.start.at_rest || !chk.end.at_rest)
    rec.warn(fmt::format("excitation: the exported trajectory ({}) does not {}:\n{}",
                         opt.export_dir.string(),
                         !chk.start.at_rest && !chk.end.at_rest ? "start or end at rest"
                         : !chk.start.at_rest                   ? "start at rest"
                                                                : "end at rest",
                         chk.restText()));
  return E;
}

}  // namespace

void record(const StageEnv& env, const ExcitationStageOut& x, StudyRecord& rec) {
  if (!x.ran) return;
  StudySummary& T = *rec.typed;
  const OptimizerResult& r = x.result;
  T.excitation = x.summary;
  for (const std::string& w : x.warnings) rec.warn(w);
  Json& X = (*rec.summary)["excitation"];
  renderInto(x.summary, &X);
  if (x.known_information) X["known_information"] = *x.known_information;
  X["details"] = r.details;
  X["history"]["t_s"] = Json(r.history_t_s);
  X["history"]["value"] = Json(r.history_value);
  if (env.write()) {
    writeExcitationFiles(env.dir, x);
    X["trajectory_csv"] = "trajectory_optimal.csv";
  }
  if (!env.opt.export_dir.empty()) X["export"] = exportExcitation(env, x, rec);
  if (!rec.report) return;
  rec.report->excitation(x.initial, x.best, r, *x.model);
  if (x.options.torque_margin > 0 || X.find("export"))
    rec.report->excitationLimits(x.best, x.tau, x.tau_max, x.options.torque_margin,
                                 X.find("export"));
  if (x.options.collision) rec.report->excitationCollision(x.best, x.min_distance, x.summary);
}

}  // namespace exid
