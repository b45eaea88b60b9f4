// exid — datasets in memory or streamed: slices, materialising a stream, ordered windows.
#include "exid/data.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "exid/error.hpp"

namespace exid {

namespace {
Eigen::MatrixXd rowsOf(const Eigen::MatrixXd& M, int begin, int end) {
  if (M.cols() == 0 || M.rows() == 0) return Eigen::MatrixXd(0, 0);
  return M.middleRows(begin, end - begin);
}

// Samples [begin, end) of d's matrices, named source with meta and facts.
Dataset samplesOf(const Dataset& d, int begin, int end, const std::string& source, const Json& meta,
                  const DatasetFacts& facts) {
  Dataset s;
  s.t = d.t.segment(begin, end - begin);
  s.q = rowsOf(d.q, begin, end);
  s.qd = rowsOf(d.qd, begin, end);
  s.qdd = rowsOf(d.qdd, begin, end);
  s.tau = rowsOf(d.tau, begin, end);
  s.wrench = rowsOf(d.wrench, begin, end);
  s.base = rowsOf(d.base, begin, end);
  s.contact = rowsOf(d.contact, begin, end);
  s.source = source;
  s.meta = meta;
  s.facts = facts;
  return s;
}

// Appends the rows of b to a (same signals).
void append(Eigen::MatrixXd* a, const Eigen::MatrixXd& b) {
  if (b.rows() == 0 || b.cols() == 0) return;
  if (a->rows() == 0) {
    *a = b;
    return;
  }
  const Eigen::Index r = a->rows();
  a->conservativeResize(r + b.rows(), Eigen::NoChange);
  a->bottomRows(b.rows()) = b;
}

// Drops the first m rows of a.
void dropFront(Eigen::MatrixXd* a, Eigen::Index m) {
  if (a->rows() == 0 || m == 0) return;
  const Eigen::Index left = a->rows() - m;
  Eigen::MatrixXd rest = a->bottomRows(left);
  a->swap(rest);
}
}  // namespace

std::vector<PartRange> partRanges(const Eigen::VectorXd& t, const DatasetFacts& facts) {
  const int K = static_cast<int>(t.size());
  std::vector<PartRange> out;
  if (facts.parts.size() < 2) {
    out.push_back({0, K, 0});
    return out;
  }
  const double* b = t.data();
  int from = 0;
  for (std::size_t i = 0; i < facts.parts.size(); ++i) {
    const int to =
        i + 1 < facts.parts.size()
            ? static_cast<int>(std::lower_bound(b + from, b + K, facts.parts[i + 1].t_from_s) - b)
            : K;
    if (to > from) out.push_back({from, to, static_cast<int>(i)});
    from = to;
  }
  return out;
}

void requireOnePart(const Dataset& d, const std::string& who, const std::string& why) {
  const std::size_t n = d.facts.parts.size();
  if (n < 2) return;
  std::string names;
  for (const DatasetPart& p : d.facts.parts) names += (names.empty() ? "" : ", ") + p.source;
  throw Error(
      fmt::format("{}: the data is {} separate recordings ({}), and {}", who, n, names, why));
}

namespace {
double medianStep(const Eigen::VectorXd& t) {
  std::vector<double> dt(static_cast<std::size_t>(t.size() - 1));
  for (Eigen::Index k = 1; k < t.size(); ++k) dt[static_cast<std::size_t>(k - 1)] = t[k] - t[k - 1];
  std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
  return dt[dt.size() / 2];
}

void appendRows(Eigen::MatrixXd* all, const Eigen::MatrixXd& part, Eigen::Index at) {
  if (part.size() > 0) all->middleRows(at, part.rows()) = part;
}
}  // namespace

Dataset joinParts(std::vector<Dataset> parts, const std::string& who) {
  check(!parts.empty(), fmt::format("{}: no recording to join", who));
  if (parts.size() == 1) return std::move(parts.front());
  const Dataset& a = parts.front();
  Eigen::Index K = 0;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const Dataset& p = parts[i];
    const std::string name = fmt::format("{}: part {} ({})", who, i + 1, p.source);
    check(!p.streamed(), name + ": a streamed recording cannot be a part (it is read in memory)");
    check(p.size() >= 2,
          fmt::format("{}: {} sample(s); a part needs at least two", name, p.size()));
    check(p.facts.parts.size() < 2 && !p.facts.simulated && !p.facts.payload_part_from_t_s,
          name + ": simulated data, a payload part or several parts cannot be joined to others");
    check(p.dof() == a.dof(), fmt::format("{}: {} joints, part 1 has {}", name, p.dof(), a.dof()));
    auto sig = [](const Dataset& d) {
      return fmt::format("q{}{}{}{}", d.hasVelocity() ? ", qd" : "",
                         d.hasAcceleration() ? ", qdd" : "", d.hasTorque() ? ", tau" : "",
                         d.hasWrench() ? ", wrench" : "") +
             (d.hasBase() ? fmt::format(", base ({})", d.base.cols()) : std::string()) +
             (d.hasContact() ? fmt::format(", contact ({})", d.contact.cols()) : std::string());
    };
    check(sig(p) == sig(a), fmt::format("{}: signals {}, part 1 has {} (every part needs the same)",
                                        name, sig(p), sig(a)));
    K += p.size();
  }
  Dataset out;
  out.t.resize(K);
  auto sized = [&](const Eigen::MatrixXd& M) {
    return M.size() > 0 ? Eigen::MatrixXd(K, M.cols()) : Eigen::MatrixXd();
  };
  out.q = sized(a.q);
  out.qd = sized(a.qd);
  out.qdd = sized(a.qdd);
  out.tau = sized(a.tau);
  out.wrench = sized(a.wrench);
  out.base = sized(a.base);
  out.contact = sized(a.contact);
  Json meta = Json::object(), files = Json::array(), pm = Json::array(), warnings = Json::array(),
       notes = Json::array();
  Eigen::Index at = 0;
  double shift = 0.0, prev_end = 0.0, prev_step = 0.0;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    Dataset& p = parts[i];
    const Eigen::Index Kp = p.size();
    if (i > 0) shift = prev_end + prev_step - p.t[0];
    out.t.segment(at, Kp) = p.t.array() + shift;
    appendRows(&out.q, p.q, at);
    appendRows(&out.qd, p.qd, at);
    appendRows(&out.qdd, p.qdd, at);
    appendRows(&out.tau, p.tau, at);
    appendRows(&out.wrench, p.wrench, at);
    appendRows(&out.base, p.base, at);
    appendRows(&out.contact, p.contact, at);
    out.facts.parts.push_back({out.t[at], p.source});
    const std::string tag = fmt::format("part {} ({})", i + 1, p.source);
    for (const char* key : {"warnings", "notes"})
      if (const Json* w = p.meta.find(key); w && w->isArray())
        for (std::size_t j = 0; j < w->size(); ++j)
          (std::string(key) == "warnings" ? warnings : notes)
              .push_back(Json(tag + ": " + w->at(j).asString()));
    Json e = Json::object();
    e["source"] = p.source;
    e["samples"] = static_cast<long long>(Kp);
    e["t_s"] = Json(std::vector<double>{out.t[at], out.t[at + Kp - 1]});
    e["time_shift_s"] = shift;
    e["meta"] = std::move(p.meta);
    pm.push_back(std::move(e));
    files.push_back(Json(p.source));
    prev_end = out.t[at + Kp - 1];
    prev_step = medianStep(p.t);
    at += Kp;
  }
  std::string source;
  for (const DatasetPart& p : out.facts.parts) source += (source.empty() ? "" : " + ") + p.source;
  out.source = source;
  meta["file"] = files;
  meta["samples"] = static_cast<long long>(K);
  if (const Json* s = parts.front().meta.find("signals")) meta["signals"] = *s;
  meta["parts_rule"] =
      "each part is read, segmented, split, resampled, filtered and trimmed on its own; part i "
      "starts one median time step of part i - 1 after it ends (time_shift_s); no model or "
      "estimator filters, differentiates, integrates or simulates across a boundary";
  meta["parts"] = std::move(pm);
  if (warnings.size() > 0) meta["warnings"] = std::move(warnings);
  if (notes.size() > 0) meta["notes"] = std::move(notes);
  out.meta = std::move(meta);
  return out;
}

Dataset sliceDataset(const Dataset& d, int begin, int end) {
  check(!d.streamed(), "sliceDataset: a streamed dataset has no samples in memory");
  check(0 <= begin && begin <= end && end <= d.size(),
        fmt::format("sliceDataset: rows [{}, {}) outside a dataset of {}", begin, end, d.size()));
  return samplesOf(d, begin, end, d.source, d.meta, d.facts);
}

Dataset materialize(const Dataset& d) {
  if (!d.streamed()) return d;
  DatasetStream& s = *d.stream;
  const int K = s.size(), n = s.dof();
  Dataset out;
  out.t.resize(K);
  out.q.resize(K, n);
  if (s.hasVelocity()) out.qd.resize(K, n);
  if (s.hasAcceleration()) out.qdd.resize(K, n);
  if (s.hasTorque()) out.tau.resize(K, n);
  if (s.hasWrench()) out.wrench.resize(K, 6);
  s.rewind();
  Dataset chunk;
  int at = 0;
  constexpr int kChunk = 8192;
  for (int got; (got = s.read(kChunk, &chunk)) > 0; at += got) {
    check(at + got <= K, fmt::format("{}: the stream gave more than its {} samples", d.source, K));
    out.t.segment(at, got) = chunk.t;
    out.q.middleRows(at, got) = chunk.q;
    if (s.hasVelocity()) out.qd.middleRows(at, got) = chunk.qd;
    if (s.hasAcceleration()) out.qdd.middleRows(at, got) = chunk.qdd;
    if (s.hasTorque()) out.tau.middleRows(at, got) = chunk.tau;
    if (s.hasWrench()) out.wrench.middleRows(at, got) = chunk.wrench;
    // a floating base's signals (a stream that gives them: the csv experiment's)
    for (auto [dst, src] : {std::pair{&out.base, &chunk.base}, {&out.contact, &chunk.contact}}) {
      if (src->cols() == 0) continue;
      if (dst->cols() == 0) *dst = Eigen::MatrixXd::Zero(K, src->cols());
      check(dst->cols() == src->cols(),
            fmt::format("{}: the stream's chunks differ in their floating-base columns", d.source));
      dst->middleRows(at, got) = *src;
    }
  }
  check(at == K, fmt::format("{}: the stream gave {} of its {} samples", d.source, at, K));
  out.source = d.source;
  out.meta = s.meta();
  out.facts = d.facts;
  return out;
}

Dataset resampleUniform(const Dataset& d, double rate_hz, const std::string& who) {
  check(!d.streamed(), "resampleUniform: a streamed dataset has no samples in memory");
  requireOnePart(d, who,
                 "resampling interpolates between neighbouring samples: resample each recording "
                 "on its own before they are joined");
  const Eigen::Index K = d.t.size();
  check(K >= 2, fmt::format("{}: resample_hz needs two samples", who));
  const double t0 = d.t[0], span_s = d.t[K - 1] - t0;
  // (counted in double first: a huge rate must not overflow the integer count). The size is
  // checked before anything is allocated: at most kMaxValues values per signal (samples x
  // joints, as the simulate experiment), whatever the rate: each signal (q, qd, qdd, tau, the
  // wrench) is then held at once, and the stages after it hold several more of its size.
  constexpr double kMaxValues = 2e7;
  const double Md = std::floor(span_s * rate_hz + 1e-9) + 1.0;
  const double cols = static_cast<double>(std::max<Eigen::Index>(1, d.q.cols()));
  check(Md >= 2.0, fmt::format("{}: resample_hz = {} gives {:g} samples over {} s (at least 2 "
                               "are needed)",
                               who, rate_hz, Md, span_s));
  check(Md * cols <= kMaxValues,
        fmt::format("{}: resample_hz = {} gives {:g} samples over {} s x {:g} joints = {:g} "
                    "values per signal, more than the cap of {:g}; lower resample_hz (at most "
                    "{:g} Hz here) or cut the segment (t_start_s, t_end_s)",
                    who, rate_hz, Md, span_s, cols, Md * cols, kMaxValues,
                    std::floor((kMaxValues / cols - 1.0) / std::max(span_s, 1e-300))));
  const auto M = static_cast<Eigen::Index>(Md);
  Dataset u;
  u.t.resize(M);
  for (Eigen::Index m = 0; m < M; ++m) u.t[m] = t0 + static_cast<double>(m) / rate_hz;
  auto interp = [&](const Eigen::MatrixXd& A) {
    if (A.size() == 0) return Eigen::MatrixXd();
    Eigen::MatrixXd B(M, A.cols());
    Eigen::Index k = 0;
    for (Eigen::Index m = 0; m < M; ++m) {
      while (k + 2 < K && d.t[k + 1] <= u.t[m]) ++k;
      const double a = (u.t[m] - d.t[k]) / (d.t[k + 1] - d.t[k]);
      B.row(m) = (1.0 - a) * A.row(k) + a * A.row(k + 1);
    }
    return B;
  };
  u.q = interp(d.q);
  u.qd = interp(d.qd);
  u.qdd = interp(d.qdd);
  u.tau = interp(d.tau);
  u.wrench = interp(d.wrench);
  u.base = interp(d.base);
  u.contact = interp(d.contact);
  u.source = d.source;
  u.meta = d.meta;
  u.facts = d.facts;
  return u;
}

void describeFacts(const DatasetFacts& f, Json* meta) {
  Json& m = *meta;
  m["simulated"] = f.simulated.has_value();
  if (f.simulated) {
    const PlantTruth& p = *f.simulated;
    m["drive_terms"] = p.drive_terms;
    const LoadMass& L = p.payload;
    Json pl = Json::object();
    pl["mass_kg"] = L.mass_kg;
    pl["com_m"] = Json(std::vector<double>{L.com_m[0], L.com_m[1], L.com_m[2]});
    const Eigen::Matrix3d& I = L.inertia_com_kg_m2;
    pl["inertia_com_kg_m2"] =
        Json(std::vector<double>{I(0, 0), I(0, 1), I(0, 2), I(1, 1), I(1, 2), I(2, 2)});
    m["payload"] = pl;
    auto perDrive = [&](const char* key, const std::vector<double>& v) {
      if (!v.empty()) m[key] = Json(v);
    };
    perDrive("coulomb_negative_Nm", p.coulomb_negative_Nm);
    perDrive("stribeck_Nm", p.stribeck_Nm);
    perDrive("coulomb_load_Nm_per_Nm", p.coulomb_load_Nm_per_Nm);
    perDrive("recorded_torque_gain", p.recorded_torque_gain);
    perDrive("drive_torque_gain", p.drive_torque_gain);
  }
  if (f.payload_part_from_t_s) m["payload_part_from_t_s"] = *f.payload_part_from_t_s;
}

SampleWindow::SampleWindow(const Dataset& d) : d_(d) {}

Dataset SampleWindow::span(int begin, int end) {
  check(
      0 <= begin && begin <= end && end <= d_.size(),
      fmt::format("SampleWindow: samples [{}, {}) outside a dataset of {}", begin, end, d_.size()));
  if (!d_.streamed()) return sliceDataset(d_, begin, end);
  DatasetStream& s = *d_.stream;
  if (!started_) {
    s.rewind();
    buf_ = Dataset();
    buf_begin_ = 0;
    started_ = true;
  }
  check(begin >= buf_begin_,
        fmt::format("SampleWindow: samples from {} asked for after samples from {} (a stream is "
                    "read in order)",
                    begin, buf_begin_));
  // Forget what no later span can ask for.
  const int have = static_cast<int>(buf_.t.size());
  const int drop = std::min(have, begin - buf_begin_);
  if (drop > 0) {
    const Eigen::Index left = have - drop;
    Eigen::VectorXd t = buf_.t.tail(left);
    buf_.t.swap(t);
    for (Eigen::MatrixXd* M : {&buf_.q, &buf_.qd, &buf_.qdd, &buf_.tau, &buf_.wrench})
      dropFront(M, drop);
  }
  buf_begin_ += drop;
  if (buf_begin_ < begin) {  // skip samples never asked for
    Dataset skip;
    while (buf_begin_ < begin) {
      const int got = s.read(std::min(8192, begin - buf_begin_), &skip);
      check(got > 0, fmt::format("{}: the stream ended at sample {} of {}", d_.source, buf_begin_,
                                 d_.size()));
      buf_begin_ += got;
    }
  }
  Dataset chunk;
  while (buf_begin_ + buf_.t.size() < end) {
    const int need = end - buf_begin_ - static_cast<int>(buf_.t.size());
    const int got = s.read(need, &chunk);
    check(got > 0, fmt::format("{}: the stream ended at sample {} of {}", d_.source,
                               buf_begin_ + static_cast<int>(buf_.t.size()), d_.size()));
    if (buf_.t.size() == 0) {
      buf_.t = chunk.t;
      buf_.q = chunk.q;
      buf_.qd = chunk.qd;
      buf_.qdd = chunk.qdd;
      buf_.tau = chunk.tau;
      buf_.wrench = chunk.wrench;
    } else {
      const Eigen::Index r = buf_.t.size();
      buf_.t.conservativeResize(r + got);
      buf_.t.tail(got) = chunk.t;
      append(&buf_.q, chunk.q);
      append(&buf_.qd, chunk.qd);
      append(&buf_.qdd, chunk.qdd);
      append(&buf_.tau, chunk.tau);
      append(&buf_.wrench, chunk.wrench);
    }
  }
  return samplesOf(buf_, begin - buf_begin_, end - buf_begin_, d_.source, d_.meta, d_.facts);
}

}  // namespace exid
