// exid — robot plugin `dh`: a robot from a DH or modified-DH YAML table (see docs/robots.md).
#include "robot_plugin_common.hpp"

namespace {

class DhRobot : public exid::Robot {
 public:
  static constexpr const char* kName = "dh";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDoc =
      "robot from a DH / modified DH YAML table (inertia, limits, drives, transmission, sensor "
      "frame)";
  static std::vector<exid::ParamDecl> params() {
    auto p = exid::robots::commonParams();
    p.insert(p.begin(), exid::param_path("file", std::nullopt,
                                         "the DH YAML file (relative paths: to the study file)"));
    return p;
  }
  explicit DhRobot(const exid::ParamSet& p) : file_(p.getString("file")), opt_(p) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext& ctx) override {
    std::filesystem::path f(file_);
    if (f.is_relative() && !ctx.study_dir.empty()) f = ctx.study_dir / f;
    return opt_.build([&](const exid::LoadOptions& o) { return exid::loadDhYaml(f, o); });
  }

 private:
  std::string file_;
  exid::robots::CommonOptions opt_;
};

}  // namespace

EXID_REGISTER_PLUGIN(DhRobot)
