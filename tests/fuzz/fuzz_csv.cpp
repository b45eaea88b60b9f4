// Fuzz target: the CSV reader (exid::parseCsv, every option) and the `csv` experiment plugin.
// Input: "<params YAML>\n%%\n<file in.csv>[\n%%\n<torque file tau.csv>]". The files are written
// to a per-process temporary folder, which is the study folder (`file: in.csv`, added to a flow
// map of parameters that does not name a file). Robot: two
// revolute joints with a transmission (DH YAML below).
#include <unistd.h>

#include <fstream>

#include "exid/config.hpp"
#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/io.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/runner.hpp"
#include "fuzz_common.hpp"

namespace {

const char* kRobot = R"(
name: fuzz2
convention: standard
links:
  - {a: 1, mass: 1, com: [-0.5, 0, 0], inertia_com: {xx: 0, yy: 0.08, zz: 0.08}, drive: {viscous: 0.1}}
  - {a: 1, mass: 1, com: [-0.5, 0, 0], inertia_com: {xx: 0, yy: 0.08, zz: 0.08}}
transmission: {matrix: [[0.5, 0], [-0.5, 1]]}
)";

std::filesystem::path dir() {
  static const std::filesystem::path d = [] {
    auto p = std::filesystem::temp_directory_path() / ("exid_fuzz_csv_" + std::to_string(getpid()));
    std::filesystem::create_directories(p);
    return p;
  }();
  return d;
}

void write(const std::filesystem::path& p, const std::string& s) {
  std::ofstream o(p, std::ios::binary | std::ios::trunc);
  o << s;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string in = exid_fuzz::text(data, size);
  // 1. parseCsv on the whole input with options from its length.
  for (int mode = 0; mode < 3; ++mode) {
    exid::CsvReadOptions o;
    o.allow_non_finite = mode == 1;
    o.drop_non_finite_rows = mode == 2;
    int dropped = 0;
    try {
      const exid::CsvTable t = exid::parseCsv(in, "fuzz.csv", o, &dropped);
      (void)exid::toCsv(t);
    } catch (const exid::Error&) {
    }
  }
  // 2. the csv experiment.
  const std::size_t a = in.find("\n%%\n");
  if (a == std::string::npos) return 0;
  std::string params = in.substr(0, a);
  // `file` is required: without it every seed stopped at parameter resolution and the plugin
  // (trim_edges, the cut-off, ...) was never reached. A flow map without it gets `file: in.csv`.
  bool names_file = false;
  for (std::size_t at = params.find("file:"); at != std::string::npos && !names_file;
       at = params.find("file:", at + 1))
    names_file = at == 0 || params[at - 1] == '{' || params[at - 1] == ' ' || params[at - 1] == ',';
  if (!params.empty() && params[0] == '{' && !names_file) params.insert(1, "file: in.csv, ");
  std::string rest = in.substr(a + 4), tau;
  const std::size_t b = rest.find("\n%%\n");
  if (b != std::string::npos) {
    tau = rest.substr(b + 4);
    rest = rest.substr(0, b);
  }
  write(dir() / "in.csv", rest);
  write(dir() / "tau.csv", tau);
  static const auto robot =
      std::make_shared<const exid::RobotModel>(exid::loadDhYamlString(kRobot, "fuzz2.yaml"));
  try {
    exid::Registry& reg = exid_fuzz::registry();
    const exid::PluginInfo& info = reg.get(exid::PluginKind::Experiment, "csv");
    const exid::ParamSet ps = exid::resolveParams(info, params, "experiment csv", dir());
    auto exp = reg.create<exid::Experiment>("csv", ps);
    exid::RunContext ctx;
    ctx.study_dir = dir();
    const exid::Dataset d = exp->run(robot, nullptr, ctx);
    (void)exid::datasetTable(d);
  } catch (const exid::Error&) {
  }
  return 0;
}
