// exid — the shared declarations of the compiled module exid._exid: module.cpp (the module, the
// plugin registry, plugins and logging), robot.cpp (exid.Robot: robots, their parameters and
// dynamics vectorised over samples), studies.cpp (studies, matrices, CSV files).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <Eigen/Core>

#include "exid/registry.hpp"

namespace py = pybind11;

namespace exid_python {

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using InArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using OutArray = py::array_t<double, py::array::c_style>;

/// The process's plugin registry (module.cpp), scanned on first use.
exid::Registry& registry();

/// The bindings of robot.cpp (the class Robot) and studies.cpp (run_study, resolved_study,
/// run_matrix, read_csv).
void bindRobot(py::module_& m);
void bindStudies(py::module_& m);

}  // namespace exid_python
