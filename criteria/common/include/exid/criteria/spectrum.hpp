// Shared by the criterion plugins: the eigen-decomposition of the information matrix
// M = W^T W (symmetric positive semi-definite) and a check that it is usable.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/interfaces.hpp"
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

/// What every criterion of the information matrix's spectrum shares: the `scale_columns`
/// parameter and the capabilities it gives. A criterion derives from it and adds kName,
/// kVersion, kDoc and evaluate().
class SpectralCriterion : public Criterion {
 public:
  static std::vector<ParamDecl> params() { return {scaleColumnsParam()}; }
  explicit SpectralCriterion(const ParamSet& p, bool condition_number = false)
      : scale_(p.getBool("scale_columns")), condition_number_(condition_number) {}
  CriterionSpecs specs() const override {
    CriterionSpecs sp;
    sp.scale_columns = scale_;
    sp.condition_number = condition_number_;
    return sp;
  }

 private:
  bool scale_;
  bool condition_number_;
};

}  // namespace exid::criteria
