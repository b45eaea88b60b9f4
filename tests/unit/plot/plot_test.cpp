// The plot layer (framework/plot: private to the core, its symbols not exported by
// libexid_core): this test links the layer's objects itself (tests/CMakeLists.txt).
#include "plot.hpp"  // framework/plot/src

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

// Drawing a plot runs gnuplot in a child process; the child must not flush the parent's
// buffered standard output a second time (it did, once per plot, when stdout was a pipe or a
// file: every report repeated what the program had printed before it).
TEST(Plot, GnuplotChildDoesNotRepeatTheParentsBufferedOutput) {
  if (exid::gnuplotProgram().empty()) GTEST_SKIP() << "gnuplot is not installed";
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("exid_plot_stdout_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string out = (dir / "stdout.txt").string();
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {  // a process whose stdout is a file (fully buffered)
    if (!std::freopen(out.c_str(), "w", stdout)) ::_exit(3);
    std::printf("before the plots\n");  // buffered, not yet written
    exid::PlotSpec s;
    s.series.push_back(exid::plotLine("y", {0.0, 1.0, 2.0}, {1.0, 2.0, 0.5}));
    for (int i = 0; i < 3; ++i) {
      s.name = "p" + std::to_string(i);
      exid::drawPlot(s, dir);
    }
    std::fflush(stdout);  // the buffered line, written once by this process
    ::_exit(0);           // (no exit handlers of the test program in the child)
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  std::ifstream in(out);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text, "before the plots\n");
  EXPECT_TRUE(std::filesystem::exists(dir / "plots" / "p2.svg"));
  std::filesystem::remove_all(dir);
}
