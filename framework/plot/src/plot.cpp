#include "plot.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>

#include "exid/error.hpp"
#include "exid/io.hpp"

namespace exid {

namespace fs = std::filesystem;

std::string gnuplotProgram() {
  if (const char* env = std::getenv("EXID_GNUPLOT")) {
    std::string s = env;
    if (s == "none" || s.empty()) return "";
    return s;
  }
  const char* path = std::getenv("PATH");
  std::string p = path ? path : "/usr/bin:/bin";
  std::size_t start = 0;
  while (start <= p.size()) {
    std::size_t end = p.find(':', start);
    if (end == std::string::npos) end = p.size();
    fs::path candidate = fs::path(p.substr(start, end - start)) / "gnuplot";
    if (::access(candidate.c_str(), X_OK) == 0) return candidate.string();
    start = end + 1;
  }
  return "";
}

namespace {

std::string quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

int runGnuplot(const std::string& program, const fs::path& script) {
  // The child must not touch the parent's stdio buffers: freopen() on stdout would flush what
  // the parent had buffered (a pipe or file is fully buffered) a second time, once per plot.
  std::fflush(nullptr);
  pid_t pid = ::fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    // gnuplot writes nothing we need on stdout/stderr; keep the terminal clean.
    const int null = ::open("/dev/null", O_WRONLY);
    if (null >= 0) {
      ::dup2(null, STDOUT_FILENO);
      ::dup2(null, STDERR_FILENO);
    }
    ::execl(program.c_str(), program.c_str(), script.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

PlotOutcome drawPlot(const PlotSpec& spec, const fs::path& dir) {
  PlotOutcome out;
  const fs::path plots = dir / "plots";
  fs::create_directories(plots);
  // Data: columns x_i, y_i (or x_i, low_i, high_i for bands), padded with nan.
  std::size_t rows = 0;
  for (const auto& s : spec.series) rows = std::max(rows, s.x.size());
  std::string csv;
  std::vector<int> first_col;
  int col = 1;
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    const auto& s = spec.series[i];
    std::string t = s.title;
    for (char& c : t)
      if (c == ',' || c == '"') c = ' ';
    first_col.push_back(col);
    if (s.style == "band") {
      csv += fmt::format("{}{}_x,{}_low,{}_high", i ? "," : "", t, t, t);
      col += 3;
    } else {
      csv += fmt::format("{}{}_x,{}_y", i ? "," : "", t, t);
      col += 2;
    }
  }
  csv += "\n";
  auto num = [](const std::vector<double>& v, std::size_t r) {
    return r < v.size() && std::isfinite(v[r]) ? fmt::format("{}", v[r]) : std::string("nan");
  };
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t i = 0; i < spec.series.size(); ++i) {
      const auto& s = spec.series[i];
      if (i) csv += ",";
      if (s.style == "band")
        csv += num(s.x, r) + "," + num(s.y_low, r) + "," + num(s.y_high, r);
      else
        csv += num(s.x, r) + "," + num(s.y, r);
    }
    csv += "\n";
  }
  writeFileAtomic(plots / (spec.name + ".csv"), csv);
  out.csv = "plots/" + spec.name + ".csv";

  const std::string program = gnuplotProgram();
  if (program.empty()) {
    out.missing_why = "gnuplot is not installed (apt-get install gnuplot-nox)";
    return out;
  }
  std::string plot_cmd;
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    const auto& s = spec.series[i];
    const int c = first_col[i];
    std::string item;
    if (s.style == "band")
      item = fmt::format(
          "{} using {}:{}:{} with filledcurves fs transparent solid 0.25 noborder title {}",
          quote((plots / (spec.name + ".csv")).string()), c, c + 1, c + 2, quote(s.title));
    else
      item = fmt::format("{} using {}:{} with {} title {}",
                         quote((plots / (spec.name + ".csv")).string()), c, c + 1,
                         s.style == "boxes" ? "boxes fs solid 0.5" : s.style, quote(s.title));
    plot_cmd += (i ? ", \\\n  " : "") + item;
  }
  auto script = [&](const std::string& terminal, const fs::path& file) {
    std::string g =
        "set datafile separator ','\nset key autotitle columnhead\nset key outside bottom center "
        "horizontal\n";
    g += "set terminal " + terminal + "\n";
    g += "set output " + quote(file.string()) + "\n";
    g += "set title " + quote(spec.title) + " noenhanced\n";
    g += "set xlabel " + quote(spec.xlabel) + " noenhanced\nset ylabel " + quote(spec.ylabel) +
         " noenhanced\n";
    g += "set grid\n";
    if (spec.log_y) g += "set logscale y\n";
    g += "plot " + plot_cmd + "\n";
    return g;
  };
  for (const auto& [ext, term] : std::vector<std::pair<std::string, std::string>>{
           {"svg", "svg size 800,420 dynamic font 'sans,11' background rgb 'white'"},
           {"png", "pngcairo size 800,420 font 'sans,10'"}}) {
    const fs::path final_file = plots / (spec.name + "." + ext);
    const fs::path tmp = plots / (spec.name + "." + ext + fmt::format(".tmp.{}", ::getpid()));
    const fs::path gp = plots / (spec.name + "." + ext + fmt::format(".gp.tmp.{}", ::getpid()));
    writeFileAtomic(gp, script(term, tmp));
    const int rc = runGnuplot(program, gp);
    fs::remove(gp);
    std::error_code ec;
    if (rc != 0 || !fs::exists(tmp) || fs::file_size(tmp, ec) == 0) {
      fs::remove(tmp, ec);
      out.missing_why =
          fmt::format("gnuplot ({}) failed with exit code {} for the {} picture", program, rc, ext);
      continue;
    }
    fs::rename(tmp, final_file, ec);
    if (ec) {
      out.missing_why = fmt::format("cannot move the {} picture into place: {}", ext, ec.message());
      continue;
    }
    (ext == "svg" ? out.svg : out.png) = "plots/" + spec.name + "." + ext;
  }
  return out;
}

}  // namespace exid
