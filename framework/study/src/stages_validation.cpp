// exid — a study's validation stage and its record (stages.hpp): the identified model's
// prediction of held-out data.
#include "stages.hpp"

namespace exid {

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

namespace {

// The held-out rows: the estimator's own processing of raw validation data, or the model's rows
// (at the fitted nonlinear parameters where the estimator fitted the model's).
Rows heldOutRows(const ObservationModel& model, const Estimate& est, Estimator& estimator,
                 const Dataset& vd, const RunContext& vctx, bool by_estimator) {
  // (fitted nonlinear parameters: the held-out rows at the fitted values; the model's own
  // come first in est.nonlinear, then the estimator's, e.g. a delay)
  // (an estimator that does not fit them, e.g. batch_ls, leaves est.nonlinear empty: rows()
  // then uses the study's values)
  // (matched by name: didim with fit_nonlinear: false reports only its delay)
  const std::vector<NonlinearParameter> model_nl = model.nonlinearParameters();
  const auto n_model = static_cast<Eigen::Index>(model_nl.size());
  bool fitted = n_model > 0 && est.nonlinear.size() >= n_model &&
                static_cast<Eigen::Index>(est.nonlinear_names.size()) >= n_model;
  for (Eigen::Index k = 0; fitted && k < n_model; ++k)
    fitted = est.nonlinear_names[static_cast<std::size_t>(k)] ==
             model_nl[static_cast<std::size_t>(k)].name;
  return by_estimator ? estimator.validationRows(model, vd, vctx)
         : fitted     ? model.rowsAt(vd, est.nonlinear.head(n_model), nullptr, vctx)
                      : model.rows(vd, vctx);
}

// One recording, two parts (split): where it was cut, and what each part holds.
Json splitJson(const StudyConfig& cfg, const Dataset& data, const Dataset& vd) {
  Json sp = Json::object();
  if (cfg.split->identification_fraction > 0)
    sp["identification_fraction"] = cfg.split->identification_fraction;
  else
    sp["at_s"] = cfg.split->at_s;
  if (const Json* m = vd.meta.find("split")) {
    for (const char* k : {"split_at_s", "identification_s", "validation_s"})
      if (const Json* x = m->find(k)) sp[k] = *x;
  }
  sp["identification_samples"] = data.size();
  sp["validation_samples"] = vd.size();
  sp["validation_overrides"] = Json(cfg.split->validation_overrides);
  sp["rule"] =
      "each part is read, filtered, differentiated and trimmed on its own: no sample of "
      "one part enters the other";
  return sp;
}

// The held-out error per equation (joint): RMS and relative to the measurement's norm.
void errorsPerEquation(const Rows& rows, const Eigen::VectorXd& err, StudySummary::Validation* va) {
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
  va->rms_per_joint = rms;
  va->relative_error_per_joint = relj;
}

// validation.csv: t of each row's sample (so that rows can be matched with other tools), the
// measurement and the prediction; the equations named in a comment line.
void writeValidationCsv(const StageEnv& env, const Rows& rows, const Eigen::VectorXd& pred) {
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
  writeFileAtomic(env.dir / "validation.csv",
                  fmt::format("# exid validation of study '{}': equation {}\n{}", env.cfg.name,
                              names.empty() ? std::string("indices") : names, toCsv(t)));
}

// A fitted measurement delay (varpro): the held-out rows are compensated by it as the fit's were
// (the model's rows read at t - delay), the samples without them dropped and counted. Returns
// summary.json validation.measurement_delay_compensation (null: no delay).
Json compensateDelay(const Estimate& est, const Dataset& vd, Rows* rows) {
  const Json* md = est.details.find("measurement_delay");
  if (!md) return Json();
  const Json* dv = md->find("value_s");
  check(dv && dv->isNumber(), "validation: the estimator's measurement_delay has no value_s");
  const double d = dv->asDouble();
  int front = 0, back = 0;
  const Dataset times = vd.streamed() ? materialize(vd) : Dataset();
  *rows = delayedRows(*rows, vd.streamed() ? times.t : vd.t, d, "validation", &front, &back);
  Json delay_meta = Json::object();
  delay_meta["delay_s"] = d;
  delay_meta["samples_without_rows_front"] = front;
  delay_meta["samples_without_rows_back"] = back;
  return delay_meta;
}

}  // namespace

ValidationStageOut validationStage(const StageEnv& env, const RobotStageOut& robot_out,
                                   const ModelStageOut& model_out,
                                   const ExperimentStageOut& experiment,
                                   const IdentificationStageOut& identification,
                                   StudyEstimator& estimator) {
  const StudyConfig& cfg = env.cfg;
  ValidationStageOut out;
  if (!cfg.validation) return out;
  env.enter("validation");
  out.ran = true;
  const auto t0 = std::chrono::steady_clock::now();
  const RobotModel& robot = *robot_out.robot;
  const ObservationModel& model = *model_out.model;
  const Estimate& est = *identification.est;
  auto exp = env.reg.create<Experiment>(cfg.validation->type, cfg.validation->params);
  RunContext vctx = env.ctx;
  vctx.seed = env.ctx.seed + 1000003;  // independent noise
  // The validation experiment runs its own trajectory (its own period, harmonics, seed):
  // validating on the identification trajectory (the excitation's optimum) would not
  // measure how the model generalises.
  Dataset vd = exp->run(robot_out.robot, nullptr, vctx);
  // Raw validation data (no q̇/q̈ yet) for an estimator that processes its own data: its
  // processing makes the validation rows too (the held-out error is then measured on rows
  // processed like the identification rows). Otherwise the model's rows of the data as
  // the validation experiment gives them.
  Estimator& vest = estimator.get();
  const bool by_estimator =
      vest.specs().needs_raw_dataset && (!vd.hasVelocity() || !vd.hasAcceleration());
  checkDataset(vd, robot, &model, "validation", by_estimator);
  checkDatasetFinite(vd, "validation");
  Rows& rows = out.rows = heldOutRows(model, est, vest, vd, vctx, by_estimator);
  if (!by_estimator) {
    if (Json delay = compensateDelay(est, vd, &rows); !delay.isNull()) out.delay = delay;
  }
  Eigen::VectorXd& pred = out.predicted = rows.W * est.value;
  // Columns that hold the recorded torque itself (drive gains dK, load-dependent Coulomb FcL):
  // W theta would predict the torque from its own measurement. The held-out prediction solves
  // the row for the torque instead (docs/estimators.md, "gains_ls").
  out.torque_prediction = predictTorqueColumns(rows, est, &pred);
  checkFinite(pred, "validation: the predicted measurement, row");
  const Eigen::VectorXd err = rows.y - pred;
  ValidationSummary& va = out.summary;
  va.type = cfg.validation->type;
  va.samples = vd.size();
  va.rows = static_cast<long long>(rows.y.size());
  out.meta = vd.meta;
  describeFacts(vd.facts, &out.meta);
  out.rows_processing =
      by_estimator ? fmt::format(
                         "the estimator's: '{}' filtered, differentiated and decimated the raw "
                         "validation data as it did its own",
                         cfg.estimator->type)
                   : std::string("the model's rows of the validation data as given");
  if (cfg.split) out.split = splitJson(cfg, *experiment.data, vd);
  out.warnings = experimentWarnings(vd, "validation");
  out.inspection = inspectionOf(robot, &model, vd, vctx);
  va.relative_error = rows.y.norm() > 0 ? err.norm() / rows.y.norm() : NAN;
  va.residual_rms =
      rows.y.size() > 0 ? err.norm() / std::sqrt(static_cast<double>(rows.y.size())) : NAN;
  errorsPerEquation(rows, err, &va);
  va.wall_s = seconds(t0);
  return out;
}

void record(const StageEnv& env, const ValidationStageOut& v, StudyRecord& rec) {
  if (!v.ran) return;
  Json& S = *rec.summary;
  rec.typed->validation = v.summary;
  Json& V = S["validation"];
  V["type"] = v.summary.type;
  V["samples"] = Json(v.summary.samples);
  V["meta"] = v.meta;
  if (v.delay) V["measurement_delay_compensation"] = *v.delay;
  if (!v.torque_prediction.empty()) V["torque_columns_prediction"] = v.torque_prediction;
  V["rows_processing"] = v.rows_processing;
  if (v.split) S["split"] = *v.split;
  for (const std::string& w : v.warnings) rec.warn(w);
  applyInspection(rec, "validation", v.inspection);
  renderInto(v.summary, &V);
  if (!v.rows.equation_names.empty()) V["equations"] = Json(v.rows.equation_names);
  if (env.write()) writeValidationCsv(env, v.rows, v.predicted);
  if (rec.report) rec.report->validation(v.rows, v.predicted, v.summary);
}

}  // namespace exid
