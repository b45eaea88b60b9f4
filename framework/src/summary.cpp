// exid — a study's typed results rendered into summary.json and the brief table (summary.hpp).
#include "exid/summary.hpp"

#include <fmt/format.h>

namespace exid {

void renderInto(const StudySummary& s, Json* S) {
  Json& o = *S;
  o["status"] = s.status;
  o["message"] = s.message;
  o["study"] = s.study;
  if (!s.failed_stage.empty()) o["failed_stage"] = s.failed_stage;
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

}  // namespace exid
