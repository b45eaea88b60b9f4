// exid — a study's experiment, identification and validation stages (study_run.hpp).
#include "study_run.hpp"

namespace exid {

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
    describeFacts(data->facts, &E["meta"]);
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
    const bool simulated_data = data->facts.simulated.has_value();
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

// A streamed recording: its statistics (and the samples kept for the inspection) are complete
// after a whole pass (the estimator's, or one more here), then inspected.
void StudyRun::completeStreamedPass(const RunContext& ictx) {
  if (!data->stream->passed()) {
    Dataset chunk;
    data->stream->rewind();
    while (data->stream->read(8192, &chunk) > 0) {
    }
  }
  data->meta = data->stream->meta();
  S["experiment"]["meta"] = data->meta;
  describeFacts(data->facts, &S["experiment"]["meta"]);
  inspectInto(S, warnFn(), "experiment", *robot, model.get(), *data, ictx);
}

// Every value of the estimate finite, else an error naming the estimator and the parameter.
void StudyRun::checkEstimateFinite() const {
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
}

// The base parameters' table of summary.json (value, std, nominal, the truth of a simulation);
// *err2 and *tru2 receive the squared error against the truth and the truth's squared norm.
Json StudyRun::parametersJson(const Eigen::VectorXd& nominal, const Eigen::VectorXd& truth,
                              bool simulated, double* err2_out, double* tru2_out) const {
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
  *err2_out = err2;
  *tru2_out = tru2;
  return params;
}

// The fitted nonlinear parameters (varpro, didim): value, std, unit and initial value.
Json StudyRun::nonlinearJson() const {
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
  return nl;
}

// What the estimate's columns say of it: the model's nonlinear parameters the estimator kept at
// the study's values, and drive-gain or load columns that hold the recorded torque.
void StudyRun::warnIdentificationColumns() {
  // the model's nonlinear parameters the estimator did not fit (matched by name)
  {
    std::string names;
    for (const auto& p : model->nonlinearParameters())
      if (std::find(est->nonlinear_names.begin(), est->nonlinear_names.end(), p.name) ==
          est->nonlinear_names.end())
        names += (names.empty() ? "" : ", ") + fmt::format("{} = {:g} {}", p.name, p.value, p.unit);
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
    if (data->streamed()) completeStreamedPass(ictx);
    checkEstimateFinite();
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
    const bool simulated = data->facts.simulated.has_value();
    const Eigen::VectorXd nominal = model->baseNominal();
    // A simulated study is judged against what the simulation used (its payload), never
    // against a nominal value it did not use.
    const Eigen::VectorXd truth =
        simulated ? Eigen::VectorXd(model->base().reduce(model->fullTruth(*data->facts.simulated)))
                  : nominal;
    double err2 = 0, tru2 = 0;
    Json params = parametersJson(nominal, truth, simulated, &err2, &tru2);
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
    if (est->nonlinear.size() > 0)  // fitted with the linear ones (varpro)
      I["nonlinear_parameters"] = nonlinearJson();
    warnIdentificationColumns();
    I["details"] = est->details;
    if (const Json* w = est->details.find("warnings"); w && w->isArray())
      for (std::size_t i = 0; i < w->size(); ++i) warn("identification: " + w->at(i).asString());
    report.identification(*est, truth, simulated);
  }
}

// The held-out rows: the estimator's own processing of raw validation data, or the model's rows
// (at the fitted nonlinear parameters where the estimator fitted the model's).
Rows StudyRun::heldOutRows(const Dataset& vd, const RunContext& vctx, bool by_estimator) {
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
  return by_estimator ? estimator().validationRows(*model, vd, vctx)
         : fitted     ? model->rowsAt(vd, est->nonlinear.head(n_model), nullptr, vctx)
                      : model->rows(vd, vctx);
}

// One recording, two parts (split): where it was cut, and what each part holds.
Json StudyRun::splitJson(const Dataset& vd) const {
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
  return sp;
}

// The held-out error per equation (joint): RMS and relative to the measurement's norm.
void StudyRun::errorsPerEquation(const Rows& rows, const Eigen::VectorXd& err,
                                 StudySummary::Validation* va) {
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
void StudyRun::writeValidationCsv(const Rows& rows, const Eigen::VectorXd& pred) const {
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
    Rows rows = heldOutRows(vd, vctx, by_estimator);
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
    describeFacts(vd.facts, &V["meta"]);
    if (!delay_meta.isNull()) V["measurement_delay_compensation"] = delay_meta;
    if (!torque_prediction.empty()) V["torque_columns_prediction"] = torque_prediction;
    V["rows_processing"] = by_estimator
                               ? fmt::format(
                                     "the estimator's: '{}' filtered, differentiated and "
                                     "decimated the raw validation data as it did its own",
                                     cfg.estimator->type)
                               : std::string("the model's rows of the validation data as given");
    if (cfg.split) S["split"] = splitJson(vd);
    for (const std::string& w : experimentWarnings(vd, "validation")) warn(w);
    inspectInto(S, warnFn(), "validation", *robot, model.get(), vd, vctx);
    va.relative_error = rows.y.norm() > 0 ? err.norm() / rows.y.norm() : NAN;
    va.residual_rms =
        rows.y.size() > 0 ? err.norm() / std::sqrt(static_cast<double>(rows.y.size())) : NAN;
    errorsPerEquation(rows, err, &va);
    va.wall_s = seconds(t0);
    renderInto(va, &V);
    if (!rows.equation_names.empty()) V["equations"] = Json(rows.equation_names);
    if (write) writeValidationCsv(rows, pred);
    report.validation(rows, pred, va);
  }
}

}  // namespace exid
