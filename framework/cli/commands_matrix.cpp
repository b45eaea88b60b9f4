// exid — the matrix commands: run a comparison matrix (in shards, or under MPI), its tables, the
// merge of shard databases.
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "exid/error.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"

namespace exid::cli {

namespace fs = std::filesystem;

namespace {

std::vector<std::string> splitComma(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

/// --shard i/N: two decimal integers, 0 <= i < N <= 100000 (nothing else on the line).
void parseShard(const std::string& shard, int* index, int* count) {
  const auto slash = shard.find('/');
  auto number = [&](const std::string& t, const char* what) {
    if (t.empty() || t.size() > 6 || t.find_first_not_of("0123456789") != std::string::npos)
      throw Error(
          fmt::format("--shard {}: {} '{}' is not a non-negative integer; expected i/N "
                      "with 0 <= i < N (e.g. --shard 0/4)",
                      shard, what, t));
    return std::stoi(t);
  };
  if (slash == std::string::npos)
    throw Error(fmt::format("--shard {}: expected i/N with 0 <= i < N (e.g. --shard 0/4)", shard));
  *index = number(shard.substr(0, slash), "i");
  *count = number(shard.substr(slash + 1), "N");
  if (*count < 1 || *count > 100000 || *index >= *count)
    throw Error(fmt::format("--shard {}: expected 0 <= i < N and 1 <= N <= 100000", shard));
}

}  // namespace

int matrixCommand(const Registry& reg, const std::vector<std::string>& args,
                  const std::string& out_arg, int jobs, const std::string& shard, bool retry,
                  bool force, const std::string& rows, const std::string& cols,
                  const std::string& metric, const std::function<bool()>& cancelled) {
  if (args.empty())
    throw Error(
        "usage: exid matrix MATRIX.yaml --out DIR [-j N] | exid matrix table DIR ... | exid matrix "
        "merge DEST SRC...");
  if (args[0] == "table") {
    if (args.size() != 2)
      throw Error("usage: exid matrix table DIR --rows A,B --cols C --metric NAME");
    const fs::path db = fs::path(args[1]) / "results.sqlite";
    if (metric.empty()) {
      std::cout << "metrics:\n";
      for (const auto& m : matrixMetrics(db)) std::cout << "  " << m << "\n";
      return 0;
    }
    MatrixTable t = matrixTable(db, splitComma(rows), splitComma(cols), metric);
    std::cout << t.markdown;
    std::string safe = metric;
    for (char& c : safe)
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') c = '_';
    const fs::path csv = fs::path(args[1]) / ("table_" + safe + ".csv");
    writeFileAtomic(csv, t.csv);
    std::cout << fmt::format("\n(CSV: {})\n", csv.string());
    return 0;
  }
  if (args[0] == "merge") {
    if (args.size() < 3) throw Error("usage: exid matrix merge DEST_DIR SRC_DIR...");
    std::vector<fs::path> srcs;
    for (std::size_t i = 2; i < args.size(); ++i)
      srcs.push_back(fs::path(args[i]) / "results.sqlite");
    int n = mergeMatrixDatabases(fs::path(args[1]) / "results.sqlite", srcs);
    std::cout << fmt::format("merged {} runs into {}/results.sqlite\n", n, args[1]);
    return 0;
  }
  if (args.size() != 1)
    throw Error("usage: exid matrix MATRIX.yaml --out DIR [-j N] [--shard i/N]");
  MatrixSpec spec = loadMatrix(args[0], reg);
  MatrixOptions opt;
  opt.out_dir = out_arg.empty() ? fs::path("out") / spec.name : fs::path(out_arg);
  if (underMpiLauncher()) {
    if (!mpiAvailable())
      throw Error(
          "exid runs under an MPI launcher but was built without MPI (install libopenmpi-dev and "
          "rebuild), "
          "or run shards with --shard i/N");
    if (!shard.empty()) throw Error("--shard and MPI both split the matrix; use one of them");
    MpiSession mpi;
    opt.jobs = std::max(1, jobs);
    opt.retry_failed = retry;
    opt.force = force;
    opt.cancelled = cancelled;
    opt.shard_index = mpi.rank;
    opt.shard_count = mpi.size;
    opt.database = fmt::format("shard-{}-of-{}.sqlite", mpi.rank, mpi.size);
    MatrixRunSummary s = runMatrix(spec, reg, opt);
    const int ok = mpi.sumInt(s.ok), failed = mpi.sumInt(s.failed), timeout = mpi.sumInt(s.timeout),
              skipped = mpi.sumInt(s.skipped), not_run = mpi.sumInt(s.not_run),
              total = mpi.sumInt(s.total);
    mpi.barrier();  // every shard database is complete
    if (mpi.rank == 0) {
      std::vector<fs::path> shards;
      for (int r = 0; r < mpi.size; ++r)
        shards.push_back(opt.out_dir / fmt::format("shard-{}-of-{}.sqlite", r, mpi.size));
      const int merged = mergeMatrixDatabases(opt.out_dir / "results.sqlite", shards);
      std::cout << fmt::format(
          "matrix {} on {} MPI ranks: {} cells: {} ok, {} failed, {} timeout, {} skipped, {} not "
          "run; "
          "{} new runs gathered into {}/results.sqlite\n",
          spec.name, mpi.size, total, ok, failed, timeout, skipped, not_run, merged,
          opt.out_dir.string());
    }
    return not_run > 0 ? signalExitCode() : 0;
  }
  opt.jobs = jobs;
  opt.retry_failed = retry;
  opt.force = force;
  opt.cancelled = cancelled;
  if (!shard.empty()) parseShard(shard, &opt.shard_index, &opt.shard_count);
  MatrixRunSummary s = runMatrix(spec, reg, opt);
  std::cout << fmt::format(
      "matrix {}: {} cells: {} ok, {} failed, {} timeout, {} skipped (finished before), {} not "
      "run; "
      "{:.2f} s\nresults: {}/results.sqlite\n",
      spec.name, s.total, s.ok, s.failed, s.timeout, s.skipped, s.not_run, s.wall_s,
      opt.out_dir.string());
  if (s.incomplete > 0)
    std::cout << fmt::format(
        "{} incomplete (no space left on device): they run again when the matrix is resumed\n",
        s.incomplete);
  return s.not_run > 0 ? signalExitCode() : 0;
}

}  // namespace exid::cli
