#include "exid/criteria/spectrum.hpp"

#include <fmt/format.h>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid::criteria {

Spectrum spectrum(const Eigen::MatrixXd& M, const char* who) {
  check(M.rows() == M.cols() && M.rows() > 0,
        fmt::format("criterion {}: information matrix must be square and non-empty, found {}x{}",
                    who, M.rows(), M.cols()));
  check(M.allFinite(), fmt::format("criterion {}: information matrix has non-finite entries", who));
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (M + M.transpose()));
  check(es.info() == Eigen::Success, fmt::format("criterion {}: eigen-decomposition failed", who));
  Spectrum s{es.eigenvalues(), es.eigenvectors()};
  check(s.lambda(0) > 1e-300 * std::max(1.0, s.lambda(s.lambda.size() - 1)),
        fmt::format("criterion {}: information matrix is singular (smallest eigenvalue {:g}); the "
                    "trajectory does not excite every base parameter",
                    who, s.lambda(0)));
  return s;
}

ParamDecl scaleColumnsParam() {
  return param_bool(
      "scale_columns", false,
      "scale each base column by the magnitude of its nominal parameter before forming M");
}

}  // namespace exid::criteria
