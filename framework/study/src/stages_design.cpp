// exid — a study's robot, model and excitation stages (study_run.hpp).
#include "study_run.hpp"

namespace exid {

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

}  // namespace exid
