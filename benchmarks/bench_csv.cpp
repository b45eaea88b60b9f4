// Reading a CSV recording: ~100 MB of numbers (13 columns: t, q1..q6, tau1..tau6) from a
// temporary file, in bytes per second of file.
//  - BM_CsvReader: exid::CsvReader, every column converted (rows into one reused buffer).
//  - BM_CsvReadCsv: exid::readCsv, the whole table (what the csv experiment pays).
//  - BM_CsvOldWay: the reference of the old reader: the file read whole into a string, then
//    std::getline + split into std::vector<std::string> + strtod per cell.
//  - BM_CsvPlainRead: read(2) of the file in 1 MB blocks, nothing parsed (the I/O floor).
// Goal: the reader >= 100 MB/s on one core. The file is in the page cache after the first pass.
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "exid/io.hpp"

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kTargetBytes = std::size_t{100} << 20;

// The file, written once: t with 6 decimals, 12 signals with 8 significant digits, ~140 bytes a
// row (the shape of the 137 MB, 1 M-sample recording of the issue "Long recordings"). Its
// directory is removed by the owner's destructor, which runs at exit while the path it holds
// still lives (a function-local static, destroyed after main returns).
class TempCsv {
 public:
  TempCsv()
      : dir_(fs::temp_directory_path() / ("exid_bench_csv_" + std::to_string(::getpid()))),
        file_(dir_ / "recording.csv") {
    fs::create_directories(dir_);
    std::ofstream o(file_, std::ios::binary | std::ios::trunc);
    o << "t,q1,q2,q3,q4,q5,q6,tau1,tau2,tau3,tau4,tau5,tau6\n";
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> u(-2.0, 2.0);
    std::size_t bytes = 0;
    fmt::memory_buffer b;
    for (long r = 0; bytes < kTargetBytes; ++r) {
      b.clear();
      fmt::format_to(std::back_inserter(b), "{:.6f}", static_cast<double>(r) * 1e-3);
      for (int c = 0; c < 12; ++c) fmt::format_to(std::back_inserter(b), ",{:.8g}", u(rng));
      b.push_back('\n');
      o.write(b.data(), static_cast<std::streamsize>(b.size()));
      bytes += b.size();
    }
  }
  ~TempCsv() {
    std::error_code ec;  // (a destructor does not throw: a failure leaves the file behind)
    fs::remove_all(dir_, ec);
  }
  TempCsv(const TempCsv&) = delete;
  TempCsv& operator=(const TempCsv&) = delete;
  const fs::path& file() const { return file_; }

 private:
  fs::path dir_;
  fs::path file_;
};

const fs::path& csvFile() {
  static const TempCsv csv;
  return csv.file();
}

std::int64_t fileBytes() { return static_cast<std::int64_t>(fs::file_size(csvFile())); }

void BM_CsvReader(benchmark::State& state) {
  const fs::path& f = csvFile();
  double sum = 0;
  for (auto _ : state) {
    exid::CsvReader reader(f);
    std::vector<double> row(reader.columns().size());
    while (reader.next(row.data())) sum += row[1];
  }
  benchmark::DoNotOptimize(sum);
  state.SetBytesProcessed(state.iterations() * fileBytes());
}
BENCHMARK(BM_CsvReader)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

void BM_CsvReadCsv(benchmark::State& state) {
  const fs::path& f = csvFile();
  for (auto _ : state) {
    exid::CsvTable t = exid::readCsv(f);
    benchmark::DoNotOptimize(t.data.data());
  }
  state.SetBytesProcessed(state.iterations() * fileBytes());
}
BENCHMARK(BM_CsvReadCsv)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// The old way, as parseCsv did it before the streaming reader (the reference).
std::string trimOld(const std::string& s) {
  std::size_t a = s.find_first_not_of(" \t\r\"");
  if (a == std::string::npos) return "";
  std::size_t b = s.find_last_not_of(" \t\r\"");
  return s.substr(a, b - a + 1);
}
std::vector<std::string> splitOld(const std::string& line, char d) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : line) {
    if (c == d) {
      out.push_back(trimOld(cur));
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(trimOld(cur));
  return out;
}

void BM_CsvOldWay(benchmark::State& state) {
  const fs::path& f = csvFile();
  double sum = 0;
  for (auto _ : state) {
    std::ifstream in(f, std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::istringstream ls(text);
    std::string line;
    bool header = false;
    std::vector<double> values;
    while (std::getline(ls, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (trimOld(line).empty() || line[0] == '#') continue;
      const auto cells = splitOld(line, ',');
      if (!header) {
        header = true;
        continue;
      }
      for (const std::string& s : cells) {
        char* end = nullptr;
        values.push_back(std::strtod(s.c_str(), &end));
      }
    }
    sum += values.empty() ? 0.0 : values[1];
  }
  benchmark::DoNotOptimize(sum);
  state.SetBytesProcessed(state.iterations() * fileBytes());
}
BENCHMARK(BM_CsvOldWay)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

void BM_CsvPlainRead(benchmark::State& state) {
  const fs::path& f = csvFile();
  std::vector<char> buf(exid::CsvReader::kDefaultBlockBytes);
  std::size_t total = 0;
  for (auto _ : state) {
    const int fd = ::open(f.c_str(), O_RDONLY | O_CLOEXEC);
    ssize_t n = 0;
    while ((n = ::read(fd, buf.data(), buf.size())) > 0) total += static_cast<std::size_t>(n);
    ::close(fd);
  }
  benchmark::DoNotOptimize(total);
  state.SetBytesProcessed(state.iterations() * fileBytes());
}
BENCHMARK(BM_CsvPlainRead)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(5);

}  // namespace

BENCHMARK_MAIN();
