// Streaming a dataset through an observation model in chunks of samples.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <numeric>
#include <thread>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"

namespace exid::estimators {

bool modelIsPerSample(const ObservationModel& model) { return model.specs().per_sample; }

void checkRows(const Rows& rows, int p, const std::string& who, int begin) {
  // (messages built only when a check fails: this runs once per chunk)
  if (rows.W.cols() != p)
    throw Error(fmt::format("{}: the model returned {} columns, expected {} base parameters", who,
                            rows.W.cols(), p));
  if (rows.W.rows() != rows.y.size())
    throw Error(fmt::format("{}: the model returned {} rows of W but {} measurements", who,
                            rows.W.rows(), rows.y.size()));
  if (!rows.equation.empty() && rows.equation.size() != static_cast<std::size_t>(rows.y.size()))
    throw Error(fmt::format("{}: the model returned {} equation labels for {} rows", who,
                            rows.equation.size(), rows.y.size()));
  if (!rows.torque.empty() && rows.torque.size() != static_cast<std::size_t>(rows.y.size()))
    throw Error(fmt::format("{}: the model returned {} recorded torques for {} rows", who,
                            rows.torque.size(), rows.y.size()));
  // One vectorised sum is finite whenever every entry is (a NaN or inf propagates); only a
  // non-finite sum (or an overflow of finite entries) pays for the entry-by-entry search.
  if (!std::isfinite(rows.W.sum() + rows.y.sum()) && (!rows.W.allFinite() || !rows.y.allFinite())) {
    for (Eigen::Index i = 0; i < rows.W.rows(); ++i)
      if (!rows.W.row(i).allFinite() || !std::isfinite(rows.y(i)))
        throw Error(
            fmt::format("{}: observation row {} (computed from samples starting at {}) is not "
                        "finite (NaN or inf in the data?)",
                        who, i, begin));
  }
}

void forEachChunk(const ObservationModel& model, const Dataset& data, int chunk_samples,
                  const RunContext& ctx, const std::string& who, double lo, double hi,
                  const std::function<void(const Rows&, int, int)>& fn) {
  const int K = data.size();
  check(K > 0, fmt::format("{}: the dataset '{}' is empty", who, data.source));
  const int chunk = modelIsPerSample(model) ? std::max(1, chunk_samples) : K;
  SampleWindow window(data);
  for (int b = 0; b < K; b += chunk) {
    if (ctx.shouldStop())
      throw Error(fmt::format("{}: stopped after {} of {} samples ({})", who, b, K,
                              ctx.deadline.expired() ? "time budget exhausted" : "interrupted"));
    const int e = std::min(K, b + chunk);
    Rows r = (b == 0 && e == K && !data.streamed()) ? model.rows(data, ctx)
                                                    : model.rows(window.span(b, e), ctx);
    checkRows(r, model.numBase(), who, b);
    fn(r, b, e);
    ctx.report(lo + (hi - lo) * static_cast<double>(e) / K,
               fmt::format("{}: {} / {} samples", who, e, K));
  }
}

ParamDecl rankToleranceParam() {
  return param_double("rank_tolerance", 1e-8, "",
                      "a direction is unidentifiable when its singular value of the "
                      "column-scaled W is below this times the largest",
                      0.0, 1.0, true, true);
}

DelaySettings DelaySettings::from(const ParamSet& p, const std::string& who,
                                  const std::string& ends) {
  DelaySettings d;
  d.on = p.getBool("measurement_delay");
  d.initial_s = p.getDouble("measurement_delay_initial_s");
  d.max_s = p.getDouble("measurement_delay_max_s");
  check(!d.on || d.max_s > 0,
        fmt::format("{}: measurement_delay: true needs measurement_delay_max_s > 0 (how large the "
                    "delay may be: {}; exid does not guess it)",
                    who, ends));
  check(d.on || (d.max_s == 0 && d.initial_s == 0),
        fmt::format("{}: measurement_delay_initial_s or measurement_delay_max_s is given but "
                    "measurement_delay is false",
                    who));
  check(!d.on || std::abs(d.initial_s) < d.max_s,
        fmt::format("{}: measurement_delay_initial_s = {} s lies outside +-"
                    "measurement_delay_max_s = {} s",
                    who, d.initial_s, d.max_s));
  return d;
}

std::vector<ParamDecl> DelaySettings::params(const std::string& what, const std::string& bound) {
  return {
      param_bool("measurement_delay", false, what),
      param_double("measurement_delay_initial_s", 0.0, "s", "the delay the fit starts from"),
      param_double("measurement_delay_max_s", 0.0, "s", bound, 0.0),
  };
}

void checkGainPrior(const std::vector<double>& std_dev, const std::vector<double>& mean,
                    const std::string& who) {
  for (double v : std_dev)
    check(v > 0 && std::isfinite(v),
          fmt::format("{}: gain_prior_std: {} is not a positive std", who, v));
  for (double v : mean)
    check(std::isfinite(v) && v > -1.0,
          fmt::format("{}: gain_prior_dK: {} is not a gain correction above -1", who, v));
  check(mean.empty() || !std_dev.empty(),
        fmt::format("{}: gain_prior_dK is given without gain_prior_std", who));
}

Eigen::VectorXd perGain(const std::vector<double>& values, std::size_t gains, const char* key,
                        double fallback, const std::string& who) {
  check(values.empty() || values.size() == 1 || values.size() == gains,
        fmt::format("{}: {} has {} values; expected 1 or one per drive gain ({})", who, key,
                    values.size(), gains));
  Eigen::VectorXd out(static_cast<Eigen::Index>(gains));
  for (std::size_t k = 0; k < gains; ++k)
    out[static_cast<Eigen::Index>(k)] =
        values.empty() ? fallback : (values.size() == 1 ? values[0] : values[k]);
  return out;
}

EstimatorSpecs streamingSpecs() {
  EstimatorSpecs s;
  s.streams = true;  // the rows in chunks (forEachChunk, accumulateRows)
  s.accepts_prior = true;
  return s;
}

void parallelChunks(long n, int threads, const std::function<void(long)>& work,
                    const std::function<void(long)>& consume) {
  pipelineChunks(
      n, threads, [](long, Dataset*) {}, [&](long c, const Dataset&) { work(c); }, consume);
}

RowAccumulator accumulateRows(const ObservationModel& model, const Dataset& data, int chunk_samples,
                              const RunContext& ctx, const std::string& who, double lo, double hi,
                              RowAccumulator::Method method, int threads) {
  const int K = data.size();
  check(K > 0, fmt::format("{}: the dataset '{}' is empty", who, data.source));
  const int p = model.numBase();
  const bool per_sample = modelIsPerSample(model);
  const int chunk = per_sample ? std::max(1, chunk_samples) : K;
  // A task (one thread's unit, one accumulator merged in order) spans whole chunks, at least
  // kTaskSamples samples: merging costs one small QR per task.
  constexpr int kTaskSamples = 8192;
  // (and at most a sixteenth of the data, so that progress is reported along the way)
  const int span = std::min(kTaskSamples, (K + 15) / 16);
  const int task = per_sample ? std::max(chunk, (span / chunk) * chunk) : K;
  const long n = (K + task - 1) / task;
  const int T = std::max(1, threads);
  // (the chunks in flight: pipelineChunks's slots c % 2T)
  std::vector<RowAccumulator> slot(2 * static_cast<std::size_t>(T));
  auto ring = [&](long c) { return static_cast<std::size_t>(c % (2 * T)); };
  RowAccumulator total(p, method);
  // One task's rows, from src (holding samples [off, off + src->size()) of the dataset).
  auto accumulateTask = [&](long c, const Dataset& src, int off) {
    const int tb = static_cast<int>(c * task), te = std::min(K, tb + task);
    RowAccumulator a(p, method);
    for (int b = tb; b < te; b += chunk) {
      if (ctx.shouldStop())
        throw Error(fmt::format("{}: stopped after {} of {} samples ({})", who, b, K,
                                ctx.deadline.expired() ? "time budget exhausted" : "interrupted"));
      const int e = std::min(te, b + chunk);
      Rows r = (b - off == 0 && e - off == src.size())
                   ? model.rows(src, ctx)
                   : model.rows(sliceDataset(src, b - off, e - off), ctx);
      checkRows(r, p, who, b);
      a.addEquations(r.W, r.y, r.equation);
    }
    slot[ring(c)] = std::move(a);
  };
  auto merge = [&](long c) {
    total.merge(slot[ring(c)]);
    slot[ring(c)] = RowAccumulator();
    const long e = std::min<long>(K, (c + 1) * task);
    ctx.report(lo + (hi - lo) * static_cast<double>(e) / K,
               fmt::format("{}: {} / {} samples", who, e, K));
  };
  if (!data.streamed()) {
    parallelChunks(
        n, T, [&](long c) { accumulateTask(c, data, 0); }, merge);
    return total;
  }
  // A streamed dataset is read in order, task by task, beside the other tasks' rows
  // (pipelineChunks); the merge is in task order, so the result is the same for any thread
  // count. A stream that reads in pieces (DatasetStream::fetch) is parsed by the
  // tasks themselves: only the fetch of the raw rows is in order.
  DatasetStream& stream = *data.stream;
  stream.rewind();
  std::unique_ptr<DatasetStream::Piece> first = stream.fetch(std::min(K, task));
  if (first) {
    std::vector<std::unique_ptr<DatasetStream::Piece>> piece(2 * static_cast<std::size_t>(T));
    std::vector<Dataset> decoded(2 * static_cast<std::size_t>(T));
    pipelineChunks(
        n, T,
        [&](long c, Dataset*) {
          const int tb = static_cast<int>(c * task), te = std::min(K, tb + task);
          piece[ring(c)] = c == 0 ? std::move(first) : stream.fetch(te - tb);
          check(piece[ring(c)] && piece[ring(c)]->count == te - tb,
                fmt::format("{}: the stream of '{}' ended at sample {} of {}", who, data.source, tb,
                            K));
        },
        [&](long c, const Dataset&) {
          Dataset& d = decoded[ring(c)];
          stream.decode(*piece[ring(c)], &d);
          d.meta = data.meta;
          d.facts = data.facts;
          accumulateTask(c, d, static_cast<int>(c * task));
        },
        [&](long c) {
          stream.settle(*piece[ring(c)], decoded[ring(c)]);
          piece[ring(c)].reset();
          merge(c);
        });
    return total;
  }
  SampleWindow window(data);
  pipelineChunks(
      n, T,
      [&](long c, Dataset* in) {
        const int tb = static_cast<int>(c * task), te = std::min(K, tb + task);
        *in = window.span(tb, te);
      },
      [&](long c, const Dataset& in) { accumulateTask(c, in, static_cast<int>(c * task)); }, merge);
  return total;
}

void pipelineChunks(long n, int threads, const std::function<void(long, Dataset*)>& read,
                    const std::function<void(long, const Dataset&)>& work,
                    const std::function<void(long)>& consume) {
  if (n <= 0) return;
  const long T = std::max<long>(1, std::min<long>(threads, n));
  if (T == 1) {
    Dataset in;
    for (long c = 0; c < n; ++c) {
      read(c, &in);
      work(c, in);
      consume(c);
    }
    return;
  }
  // Every thread (the caller's too) claims the next chunk and reads its input (in chunk order,
  // under the lock), works on it unlocked, marks it done, and then consumes, one thread at a
  // time and in chunk order, every done chunk that is next. No thread waits for a wave: one
  // waits only when `window` chunks are claimed and not yet consumed (the slots c % window).
  const long window = 2 * T;
  std::vector<Dataset> input(static_cast<std::size_t>(window));
  std::vector<char> done(static_cast<std::size_t>(window), 0);
  std::mutex m;
  std::condition_variable cv;
  long next = 0, consumed = 0;
  bool consuming = false;
  long fail_at = n;  // the first failing chunk (n: none)
  std::exception_ptr failure;
  auto fail = [&](long c, std::exception_ptr e) {  // (under m)
    if (c < fail_at) {
      fail_at = c;
      failure = std::move(e);
    }
    cv.notify_all();
  };
  auto slot = [&](long c) { return static_cast<std::size_t>(c % window); };
  auto worker = [&] {
    std::unique_lock<std::mutex> lk(m);
    for (;;) {
      cv.wait(lk, [&] { return next >= n || fail_at < n || next - consumed < window; });
      if (next >= n || fail_at < n) return;
      const long c = next++;
      try {
        read(c, &input[slot(c)]);
      } catch (...) {
        fail(c, std::current_exception());
        return;
      }
      lk.unlock();
      std::exception_ptr err;
      try {
        work(c, input[slot(c)]);
      } catch (...) {
        err = std::current_exception();
      }
      lk.lock();
      if (err) {
        fail(c, err);
        continue;
      }
      done[slot(c)] = 1;
      while (!consuming && consumed < fail_at && done[slot(consumed)]) {
        consuming = true;
        const long k = consumed;
        lk.unlock();
        try {
          consume(k);
        } catch (...) {
          err = std::current_exception();
        }
        lk.lock();
        consuming = false;
        if (err) {
          fail(k, err);
          break;
        }
        done[slot(k)] = 0;
        ++consumed;
        cv.notify_all();
      }
    }
  };
  std::vector<std::thread> pool;
  for (long i = 1; i < T; ++i) pool.emplace_back(worker);
  worker();
  for (auto& th : pool) th.join();
  if (failure) std::rethrow_exception(failure);
  check(consumed == n, fmt::format("pipelineChunks: {} of {} chunks consumed", consumed, n));
}

void addEquationRows(const Rows& rows, const std::vector<int>& index, int eq,
                     std::map<int, RowAccumulator>* acc) {
  if (index.empty()) return;
  const auto n = static_cast<Eigen::Index>(index.size());
  const auto p = static_cast<int>(rows.W.cols());
  Eigen::MatrixXd W(n, p);
  Eigen::VectorXd y(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    W.row(k) = rows.W.row(index[static_cast<std::size_t>(k)]);
    y(k) = rows.y(index[static_cast<std::size_t>(k)]);
  }
  auto it = acc->find(eq);
  if (it == acc->end())
    it = acc->emplace(eq, RowAccumulator(p, RowAccumulator::Method::Qr, 512)).first;
  it->second.add(W, y);
}

void rowTimeOrder(const Rows& rows, int samples, std::vector<int>* sample_of_row,
                  std::vector<int>* order) {
  const auto R = static_cast<int>(rows.y.size());
  sample_of_row->assign(static_cast<std::size_t>(R), 0);
  order->resize(static_cast<std::size_t>(R));
  std::iota(order->begin(), order->end(), 0);
  if (R == 0 || samples <= 0) return;
  const bool labelled = rows.equation.size() == static_cast<std::size_t>(R);
  if (R % samples == 0 && labelled) {
    const int r = R / samples;
    bool sample_major = true, equation_major = true;
    for (int i = 0; i < R && (sample_major || equation_major); ++i) {
      const int eq = rows.equation[static_cast<std::size_t>(i)];
      if (sample_major && rows.equation[static_cast<std::size_t>(i)] !=
                              rows.equation[static_cast<std::size_t>(i % r)])
        sample_major = false;
      if (equation_major && eq != rows.equation[static_cast<std::size_t>((i / samples) * samples)])
        equation_major = false;
    }
    // A layout with one row per sample is both; distinct labels inside a sample decide.
    if (sample_major) {
      for (int i = 0; i < R; ++i) (*sample_of_row)[static_cast<std::size_t>(i)] = i / r;
      return;
    }
    if (equation_major) {
      for (int i = 0; i < R; ++i) (*sample_of_row)[static_cast<std::size_t>(i)] = i % samples;
      std::stable_sort(order->begin(), order->end(), [&](int a, int b) {
        return (*sample_of_row)[static_cast<std::size_t>(a)] <
               (*sample_of_row)[static_cast<std::size_t>(b)];
      });
      return;
    }
  }
  for (int i = 0; i < R; ++i)
    (*sample_of_row)[static_cast<std::size_t>(i)] =
        std::min(samples - 1, static_cast<int>((static_cast<long long>(i) * samples) / R));
}

}  // namespace exid::estimators
