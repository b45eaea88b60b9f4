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
  }
  check(at == K, fmt::format("{}: the stream gave {} of its {} samples", d.source, at, K));
  out.source = d.source;
  out.meta = s.meta();
  out.facts = d.facts;
  return out;
}

Dataset resampleUniform(const Dataset& d, double rate_hz, const std::string& who) {
  check(!d.streamed(), "resampleUniform: a streamed dataset has no samples in memory");
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
