// The HTML report as a person sees it: rendered headless by Chromium to a screenshot, the
// verdict before the first figure, every file it links to present.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>
#include <vector>

#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace {

// The Chromium program on PATH ("" when none).
std::string chromium() {
  const char* path = std::getenv("PATH");
  const std::string p = path ? path : "/usr/bin:/bin";
  for (const char* name : {"chromium", "chromium-browser", "google-chrome"}) {
    std::size_t start = 0;
    while (start <= p.size()) {
      std::size_t end = p.find(':', start);
      if (end == std::string::npos) end = p.size();
      const fs::path c = fs::path(p.substr(start, end - start)) / name;
      if (::access(c.c_str(), X_OK) == 0) return c.string();
      start = end + 1;
    }
  }
  return "";
}

// A PNG's width and height (0, 0 when the file is not a PNG).
std::pair<unsigned, unsigned> pngSize(const fs::path& file) {
  const std::string b = exid_cli::slurp(file);
  if (b.size() < 24 || b.compare(0, 8, "\x89PNG\r\n\x1a\n") != 0) return {0, 0};
  auto be32 = [&](std::size_t i) {
    unsigned v = 0;
    for (std::size_t k = 0; k < 4; ++k) v = (v << 8) | static_cast<unsigned char>(b[i + k]);
    return v;
  };
  return {be32(16), be32(20)};
}

// Excitation with torque limits, an experiment on the optimal trajectory, held-out validation.
const char* kStudy = R"(name: report_html
seed: 2
robot: {type: panda}
model: {type: differential, params: {viscous: true, coulomb: true}}
excitation:
  trajectory:
    type: fourier
    params: {period_s: 4, harmonics: 3, sample_period_s: 0.1, position_margin_rad: 0.1,
             velocity_limit_rad_s: 2.0, acceleration_limit_rad_s2: 7.0, rest_to_rest: true}
  criterion: {type: cond}
  optimizer: {type: nlopt, params: {algorithm: LD_SLSQP, constraint_mode: aggregated, starts: 1,
              max_evaluations: 60}}
  constraints: {torque_margin: 0.6, torque_max_Nm: [87, 87, 87, 87, 12, 12, 12]}
experiment: {type: simulate, params: {sample_period_s: 0.01, noise_tau_Nm: 0.05}}
estimator: {type: batch_ls}
validation:
  type: simulate
  params: {period_s: 4, harmonics: 3, duration_s: 4, sample_period_s: 0.01, noise_tau_Nm: 0.05}
)";

}  // namespace

TEST(ReportHtml, VerdictFirstEveryLinkedFilePresentAndItRenders) {
  const fs::path dir = exid_cli::freshTempDir("exid_report_html_", "study");
  std::ofstream(dir / "study.yaml") << kStudy;
  const exid_cli::CmdResult r = exid_cli::runExid("-q run " + (dir / "study.yaml").string() +
                                                  " --out " + (dir / "out").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const fs::path html_file = dir / "out" / "report.html";
  const std::string html = exid_cli::slurp(html_file);
  ASSERT_FALSE(html.empty());

  // The verdict, then the key figures, before the first figure.
  const auto verdict = html.find("Verdict: ");
  const auto key = html.find("Key figures");
  const auto figure = html.find("<figure");
  ASSERT_NE(verdict, std::string::npos) << html.substr(0, 2000);
  ASSERT_NE(figure, std::string::npos) << "the report has figures (gnuplot is a dependency)";
  EXPECT_LT(verdict, key);
  EXPECT_LT(key, figure);
  // every figure of the validation: one per joint, and the torque limits of the design
  for (const char* f : {"validation_equation1", "validation_equation7", "torque_ratio"})
    EXPECT_NE(html.find(std::string("plots/") + f + ".png"), std::string::npos) << f;

  // Every file the HTML refers to (src=, href=) exists beside it.
  const std::regex ref("(?:src|href)=\"([^\"#:]+)\"");
  int refs = 0;
  for (auto it = std::sregex_iterator(html.begin(), html.end(), ref); it != std::sregex_iterator();
       ++it) {
    const std::string target = (*it)[1];
    ++refs;
    EXPECT_TRUE(fs::exists(dir / "out" / target)) << target;
  }
  EXPECT_GT(refs, 0);

  const std::string chrome = chromium();
  if (chrome.empty())
    GTEST_SKIP() << "chromium is not installed (apt-get install chromium; scripts/install-deps.sh "
                    "installs it): the report was checked, not rendered";
  const fs::path shot = dir / "report.png";
  const std::string cmd = "timeout 180 " + chrome +
                          " --headless --disable-gpu --no-sandbox --hide-scrollbars"
                          " --user-data-dir=" +
                          (dir / "chromium-profile").string() + " --screenshot=" + shot.string() +
                          " --window-size=1200,2000 file://" + html_file.string() + " >" +
                          (dir / "chromium.log").string() + " 2>&1";
  const int rc = std::system(cmd.c_str());
  ASSERT_EQ(rc, 0) << cmd << "\n" << exid_cli::slurp(dir / "chromium.log");
  ASSERT_TRUE(fs::exists(shot)) << exid_cli::slurp(dir / "chromium.log");
  const auto [w, h] = pngSize(shot);
  EXPECT_EQ(w, 1200u);
  EXPECT_EQ(h, 2000u);
  // Non-trivial: a blank page of that size is about 11 kB; text, tables and figures far more.
  EXPECT_GT(fs::file_size(shot), 60000u) << shot;
  fs::remove_all(dir);
}
