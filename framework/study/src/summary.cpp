// exid — a study's typed results rendered into summary.json and the brief table (summary.hpp).
#include "exid/summary.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cmath>

namespace exid {

void renderInto(const StudySummary& s, Json* S) {
  Json& o = *S;
  o["status"] = s.status;
  o["message"] = s.message;
  o["study"] = s.study;
  if (!s.failed_stage.empty()) o["failed_stage"] = s.failed_stage;
  if (!s.verdict.empty()) {
    Json v = Json::object();
    v["value"] = s.verdict;
    v["reasons"] = Json(s.verdict_reasons);
    o["verdict"] = v;
  }
  o["warnings"] = Json(s.warnings);
  if (std::isfinite(s.wall_s)) o["wall_s"] = s.wall_s;
}

void renderInto(const StudySummary::Robot& r, Json* R) {
  Json& o = *R;
  o["type"] = r.type;
  o["name"] = r.name;
  o["dof"] = r.dof;
  o["n_parameters"] = r.n_parameters;
  if (r.n_base_parameters) o["n_base_parameters"] = *r.n_base_parameters;
  if (!r.notes.empty()) o["notes"] = Json(r.notes);
  o["wall_s"] = r.wall_s;
}

void renderInto(const StudySummary::Excitation& x, Json* X) {
  Json& o = *X;
  o["trajectory"] = x.trajectory;
  o["criterion"] = x.criterion;
  o["optimizer"] = x.optimizer;
  o["criterion_initial"] = x.criterion_initial;
  o["criterion_final"] = x.criterion_final;
  o["cond_W_initial"] = x.cond_W_initial;
  o["cond_W_final"] = x.cond_W_final;
  o["max_constraint_violation"] = x.max_constraint_violation;
  o["feasible"] = x.feasible;
  if (x.torque_margin) o["torque_margin"] = *x.torque_margin;
  if (x.torque_ratio_max) o["torque_ratio_max"] = *x.torque_ratio_max;
  if (x.distance_margin_m) {
    Json& c = o["collision"];
    c["margin_m"] = *x.distance_margin_m;
    c["pairs"] = x.collision_pairs;
    c["excluded"] = Json(x.collision_excluded);
    c["min_distance_initial_m"] = x.min_distance_initial_m.value_or(NAN);
    c["min_distance_final_m"] = x.min_distance_final_m.value_or(NAN);
    c["min_distance_pair"] = x.min_distance_pair;
    Json cl = Json::array();
    for (const auto& [pair, dist] : x.closest_pairs_m) {
      Json e = Json::object();
      e["pair"] = pair;
      e["min_distance_m"] = dist;
      cl.push_back(e);
    }
    c["closest_pairs"] = cl;
  }
  o["iterations"] = x.iterations;
  o["evaluations"] = Json(x.evaluations);
  o["wall_s"] = x.wall_s;
  o["stop_reason"] = x.stop_reason_text;
  o["reproducible"] = x.reproducible;
}

void renderInto(const StudySummary::Experiment& e, Json* E) {
  Json& o = *E;
  o["type"] = e.type;
  o["samples"] = Json(e.samples);
  o["duration_s"] = e.duration_s;
  o["wall_s"] = e.wall_s;
}

void renderInto(const StudySummary::Identification& i, Json* I) {
  Json& o = *I;
  o["estimator"] = i.estimator;
  o["wall_s"] = i.wall_s;
  o["rows"] = Json(i.rows);
  o["cond_W"] = i.cond_W;
  o["residual_rms"] = i.residual_rms;
  o["sigma"] = i.sigma;
  if (i.param_abs_err) o["param_abs_err"] = *i.param_abs_err;
  if (i.param_rel_err) o["param_rel_err"] = *i.param_rel_err;
}

void renderInto(const StudySummary::Validation& v, Json* V) {
  Json& o = *V;
  o["type"] = v.type;
  o["samples"] = Json(v.samples);
  o["rows"] = Json(v.rows);
  o["relative_error"] = v.relative_error;
  o["residual_rms"] = v.residual_rms;
  o["rms_per_joint"] = Json(v.rms_per_joint);
  o["relative_error_per_joint"] = Json(v.relative_error_per_joint);
  o["wall_s"] = v.wall_s;
}

std::string briefTable(const StudySummary& s) {
  std::string out;
  auto row = [&](const std::string& k, const std::string& v) {
    out += fmt::format("| {} | {} |\n", k, v);
  };
  auto num = [](double x) {
    return std::isfinite(x) ? fmt::format("{:.6g}", x) : std::string("-");
  };
  out += "| quantity | value |\n|---|---|\n";
  row("status", s.status);
  if (!s.verdict.empty())
    row("verdict", s.verdict_reasons.empty()
                       ? s.verdict
                       : fmt::format("{}: {}", s.verdict, fmt::join(s.verdict_reasons, "; ")));
  if (s.robot) {
    row("robot", fmt::format("{} ({} dof)", s.robot->name, s.robot->dof));
    if (s.robot->n_base_parameters)
      row("base parameters",
          fmt::format("{} of {}", *s.robot->n_base_parameters, s.robot->n_parameters));
  }
  if (const auto& x = s.excitation) {
    row("excitation criterion",
        fmt::format("{} -> {} ({} iterations, {} s)", num(x->criterion_initial),
                    num(x->criterion_final), x->iterations, num(x->wall_s)));
    row("cond(W) of trajectory",
        fmt::format("{} -> {}", num(x->cond_W_initial), num(x->cond_W_final)));
  }
  if (s.experiment) row("experiment samples", std::to_string(s.experiment->samples));
  if (const auto& i = s.identification) {
    row("estimator", i->estimator);
    row("cond(W) of identification", num(i->cond_W));
    row("residual RMS", num(i->residual_rms));
    if (i->param_rel_err) row("parameter relative error", num(*i->param_rel_err));
  }
  if (s.validation) row("validation relative error", num(s.validation->relative_error));
  return out;
}

namespace {
const Json* path(const Json& j, std::initializer_list<const char*> keys) {
  const Json* cur = &j;
  for (const char* k : keys) {
    if (!cur->isObject()) return nullptr;
    cur = cur->find(k);
    if (!cur) return nullptr;
  }
  return cur;
}
double number(const Json* j) { return j && j->isNumber() ? j->asDouble() : NAN; }
}  // namespace

std::vector<std::string> verdictReasons(const Json& S) {
  std::vector<std::string> r;
  const double rel = number(path(S, {"validation", "relative_error"}));
  const double val_rms = number(path(S, {"validation", "residual_rms"}));
  const double id_rms = number(path(S, {"identification", "residual_rms"}));
  if (rel >= kVerdictHeldOutNoBetterThanZero)
    r.push_back(fmt::format(
        "the held-out relative error is {:.4g}: the identified model predicts the held-out data "
        "no better than predicting zero (>= {:g}); look for a flipped sign, a wrong scale or "
        "column, misaligned or unevenly stamped samples (`exid inspect`)",
        rel, kVerdictHeldOutNoBetterThanZero));
  else if (rel > kVerdictHeldOutMaterial && id_rms > 0 &&
           val_rms > kVerdictHeldOutOverResidual * id_rms)
    r.push_back(fmt::format(
        "the held-out RMS error ({:.4g}) is {:.3g} times the identification residual RMS "
        "({:.4g}; suspect above {:g} times): the model fits its own data but does not predict "
        "other data (overfitting, too little excitation, or parts recorded differently)",
        val_rms, val_rms / id_rms, id_rms, kVerdictHeldOutOverResidual));
  if (const Json* sus = path(S, {"identification", "details", "suspect"}); sus && sus->isArray())
    for (std::size_t i = 0; i < sus->size(); ++i)
      if (sus->at(i).isString()) r.push_back(sus->at(i).asString());
  // The fit's distance from its prior (base parameters, in the prior's covariance): for p
  // parameters drawn from the prior, d^2 is chi-square with p degrees of freedom (mean p, std
  // sqrt(2p)).
  if (const Json* pr = path(S, {"identification", "details", "prior"})) {
    const double d = number(pr->find("mahalanobis_from_prior"));
    const Json* v = pr->find("value");
    const double p = v && v->isArray() ? static_cast<double>(v->size()) : NAN;
    if (std::isfinite(d) && p > 0) {
      const double limit = p + kVerdictPriorTailSigma * std::sqrt(2.0 * p);
      if (d * d > limit)
        r.push_back(fmt::format(
            "the estimate lies far outside its prior: squared Mahalanobis distance {:.4g} for {} "
            "parameters (a chi-square of mean {} and std {:.3g}; suspect above {:.4g}): the "
            "prior's values or standard deviations, or the data, are wrong",
            d * d, static_cast<int>(p), static_cast<int>(p), std::sqrt(2.0 * p), limit));
    }
  }
  return r;
}

void judgeResults(const Json& summary, StudySummary* s) {
  s->verdict_reasons = verdictReasons(summary);
  s->verdict = s->verdict_reasons.empty() ? "ok" : "suspect";
}

}  // namespace exid
