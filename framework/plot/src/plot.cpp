#include "plot.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
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

namespace {

bool sharedX(const PlotSpec& spec) {
  if (spec.x_column.empty() || spec.series.empty()) return false;
  for (const auto& s : spec.series)
    if (s.style == "band" || s.x != spec.series.front().x) return false;
  return true;
}

std::string csvName(std::string t) {
  for (char& c : t)
    if (c == ',' || c == '"' || c == '\n') c = ' ';
  return t;
}

bool hasLowerPanel(const PlotSpec& spec) {
  for (const auto& s : spec.series)
    if (s.panel == 1) return true;
  return false;
}

// The finite extremes of values (low > high when there are none).
void extend(const std::vector<double>& v, double* low, double* high) {
  for (double x : v)
    if (std::isfinite(x)) {
      *low = std::min(*low, x);
      *high = std::max(*high, x);
    }
}

// The gnuplot columns (1-based) of each series in plotCsv's layout.
std::vector<int> firstColumns(const PlotSpec& spec) {
  std::vector<int> first;
  const bool shared = sharedX(spec);
  int col = shared ? 2 : 1;
  for (const auto& s : spec.series) {
    first.push_back(col);
    col += shared ? 1 : (s.style == "band" ? 3 : 2);
  }
  return first;
}

// One panel's plot command: its series, from the CSV.
std::string plotCommand(const PlotSpec& spec, const std::string& csv, int panel) {
  const bool shared = sharedX(spec);
  const std::vector<int> first = firstColumns(spec);
  std::string cmd;
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    const auto& s = spec.series[i];
    if (s.panel != panel) continue;
    const int c = first[i];
    std::string look;
    if (!s.color.empty()) look += " lc rgb " + quote(s.color);
    if (s.width > 0) look += fmt::format(" lw {:g}", s.width);
    std::string item;
    if (s.style == "band")
      item = fmt::format(
          "{} using {}:{}:{} with filledcurves fs transparent solid 0.25 noborder{} title {}",
          quote(csv), c, c + 1, c + 2, look, quote(s.title));
    else
      item = fmt::format("{} using {}:{} with {}{} title {}", quote(csv), shared ? 1 : c,
                         shared ? c : c + 1, s.style == "boxes" ? "boxes fs solid 0.5" : s.style,
                         look, quote(s.title));
    cmd += (cmd.empty() ? "" : ", \\\n  ") + item;
  }
  return cmd;
}

// The limits: dashed lines across the panel, each labelled at its right end (above a limit at
// or above zero, below one under it).
std::string limitLines(const PlotSpec& spec) {
  std::string g;
  for (const auto& l : spec.limits) {
    if (!std::isfinite(l.y)) continue;
    g += fmt::format(
        "set arrow from graph 0, first {0:.17g} to graph 1, first {0:.17g} nohead dt 2 lw 1.5 "
        "lc rgb {1} front\n",
        l.y, quote(l.color));
    g += fmt::format(
        "set label {} at graph 0.99, first {:.17g} right offset 0, char {} tc rgb {} front "
        "noenhanced font ',9'\n",
        quote(l.label), l.y, l.y >= 0 ? 0.6 : -0.6, quote(l.color));
  }
  return g;
}

}  // namespace

PlotRange plotYRange(const PlotSpec& spec) {
  PlotRange r;
  if (spec.limits.empty() || spec.log_y) return r;
  double low = HUGE_VAL, high = -HUGE_VAL;
  for (const auto& s : spec.series) {
    if (s.panel != 0) continue;
    extend(s.style == "band" ? s.y_low : s.y, &low, &high);
    extend(s.y_high, &low, &high);
  }
  for (const auto& l : spec.limits) extend({l.y}, &low, &high);
  if (!(low <= high)) return r;
  double pad = 0.1 * (high - low);
  if (!(pad > 0)) pad = std::abs(high) > 0 ? 0.1 * std::abs(high) : 1.0;
  r.low = low - pad;
  r.high = high + pad;
  return r;
}

std::string plotCsv(const PlotSpec& spec) {
  // Columns x_i, y_i (or x_i, low_i, high_i for bands), padded with nan; with a shared x
  // (x_column): x, then one column per series.
  const bool shared = sharedX(spec);
  std::size_t rows = 0;
  for (const auto& s : spec.series) rows = std::max(rows, s.x.size());
  std::string csv = shared ? csvName(spec.x_column) : "";
  for (std::size_t i = 0; i < spec.series.size(); ++i) {
    const auto& s = spec.series[i];
    const std::string t = csvName(s.title);
    if (shared)
      csv += "," + t;
    else if (s.style == "band")
      csv += fmt::format("{}{}_x,{}_low,{}_high", i ? "," : "", t, t, t);
    else
      csv += fmt::format("{}{}_x,{}_y", i ? "," : "", t, t);
  }
  csv += "\n";
  auto num = [](const std::vector<double>& v, std::size_t r) {
    return r < v.size() && std::isfinite(v[r]) ? fmt::format("{}", v[r]) : std::string("nan");
  };
  for (std::size_t r = 0; r < rows; ++r) {
    if (shared) csv += num(spec.series.front().x, r);
    for (std::size_t i = 0; i < spec.series.size(); ++i) {
      const auto& s = spec.series[i];
      if (shared)
        csv += "," + num(s.y, r);
      else if (s.style == "band")
        csv += (i ? "," : "") + num(s.x, r) + "," + num(s.y_low, r) + "," + num(s.y_high, r);
      else
        csv += (i ? "," : "") + num(s.x, r) + "," + num(s.y, r);
    }
    csv += "\n";
  }
  return csv;
}

std::string plotScript(const PlotSpec& spec, const std::string& csv, const std::string& terminal,
                       const std::string& output) {
  const bool lower = hasLowerPanel(spec);
  std::string g = "set datafile separator ','\nset key autotitle columnhead\n";
  g += "set terminal " + terminal + "\n";
  g += "set termoption noenhanced\n";  // names as written: joint_1 is not joint with a subscript
  g += "set output " + quote(output) + "\n";
  g += "set title " + quote(spec.title) + " noenhanced\n";
  g += "set ylabel " + quote(spec.ylabel) + " noenhanced\n";
  g += "set grid\n";
  if (spec.log_y) g += "set logscale y\n";
  const PlotRange yr = plotYRange(spec);
  if (std::isfinite(yr.low) && std::isfinite(yr.high))
    g += fmt::format("set yrange [{:.17g}:{:.17g}]\n", yr.low, yr.high);
  g += limitLines(spec);
  if (!lower) {
    g += "set key outside bottom center horizontal\n";
    g += "set xlabel " + quote(spec.xlabel) + " noenhanced\n";
    return g + "plot " + plotCommand(spec, csv, 0) + "\n";
  }
  // Two panels sharing the x axis: the series above, the residuals below.
  double x0 = HUGE_VAL, x1 = -HUGE_VAL;
  for (const auto& s : spec.series) extend(s.x, &x0, &x1);
  g += "set multiplot\nset lmargin at screen 0.11\nset rmargin at screen 0.97\n";
  if (x0 < x1) g += fmt::format("set xrange [{:.17g}:{:.17g}]\n", x0, x1);
  // (the title, then the key, above the upper panel)
  g += "unset title\nset label 100 " + quote(spec.title) +
       " at screen 0.5, screen 0.965 center noenhanced font ',12'\n";
  g += "set tmargin at screen 0.86\nset bmargin at screen 0.40\n";
  g += "set key at screen 0.5, screen 0.91 center center horizontal\nset format x ''\n"
       "unset xlabel\n";
  g += "plot " + plotCommand(spec, csv, 0) + "\n";
  g += "unset title\nunset arrow\nunset label\nunset logscale y\nset autoscale y\n";
  g += "set tmargin at screen 0.36\nset bmargin at screen 0.10\nset format x '% h'\n";
  g += "set xlabel " + quote(spec.xlabel) + " noenhanced\n";
  g += "set ylabel " + quote(spec.lower_ylabel) + " noenhanced\n";
  g += "set key inside top right horizontal opaque\n";
  g += "plot " + plotCommand(spec, csv, 1) + ", \\\n  0 with lines dt 2 lc rgb '#808080' notitle\n";
  return g + "unset multiplot\n";
}

PlotOutcome drawPlot(const PlotSpec& spec, const fs::path& dir) {
  PlotOutcome out;
  const fs::path plots = dir / "plots";
  fs::create_directories(plots);
  const fs::path csv = plots / (spec.name + ".csv");
  writeFileAtomic(csv, plotCsv(spec));
  out.csv = "plots/" + spec.name + ".csv";

  const std::string program = gnuplotProgram();
  if (program.empty()) {
    out.missing_why = "gnuplot is not installed (apt-get install gnuplot-nox)";
    return out;
  }
  const int height = hasLowerPanel(spec) ? 600 : 420;
  for (const auto& [ext, term] : std::vector<std::pair<std::string, std::string>>{
           {"svg",
            fmt::format("svg size 800,{} dynamic font 'sans,11' background rgb 'white'", height)},
           {"png", fmt::format("pngcairo size 800,{} font 'sans,10'", height)}}) {
    const fs::path final_file = plots / (spec.name + "." + ext);
    const fs::path tmp = plots / (spec.name + "." + ext + fmt::format(".tmp.{}", ::getpid()));
    const fs::path gp = plots / (spec.name + "." + ext + fmt::format(".gp.tmp.{}", ::getpid()));
    writeFileAtomic(gp, plotScript(spec, csv.string(), term, tmp.string()));
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
