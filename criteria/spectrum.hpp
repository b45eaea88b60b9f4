// Shared by the criterion plugins: the eigen-decomposition of the information matrix
// M = W^T W (symmetric positive semi-definite) and a check that it is usable.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/params.hpp"

namespace exid::criteria {

struct Spectrum {
  Eigen::VectorXd lambda;  // ascending eigenvalues of M (= squared singular values of W)
  Eigen::MatrixXd V;       // eigenvectors (columns)
};

/// Throws exid::Error when M is not square, has non-finite entries, or is singular
/// (lambda_min <= 1e-300); `who` names the criterion in the message.
Spectrum spectrum(const Eigen::MatrixXd& M, const char* who);

/// The parameter every criterion declares.
ParamDecl scaleColumnsParam();

}  // namespace exid::criteria
