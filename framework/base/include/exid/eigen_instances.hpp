// exid — Eigen's dense decompositions of MatrixXd, compiled once. Include this header instead of
// <Eigen/SVD>, <Eigen/QR>, <Eigen/Cholesky>, <Eigen/LU> or <Eigen/Eigenvalues>: the
// decompositions' non-inline code (the SVDs, the QRs' factorisations, the Cholesky and LU
// factors, the symmetric eigensolver) is instantiated once in libexid_dynamics
// (framework/base/instances/) and declared here as an explicit instantiation, so a
// file that uses them no longer instantiates and compiles them again. Measured with g++ 12 -O3
// one file at a time (docs/architecture.md, "Eigen's decompositions, compiled once"):
// estimators/common/src/least_squares.cpp 42.7 s -> 17.5 s,
// rank.cpp 25.5 s -> 2.1 s; a whole build, about 5 % of its compile CPU. The code is the same,
// compiled with the same flags as the files that used to instantiate it: the same results, bit
// for bit.
//
// Only the double, dynamic-size matrices are here: fixed-size decompositions (Matrix3d, ...) stay
// inline, where the compiler unrolls them. Decompositions of expressions (e.g. `(A * B).ldlt()`
// of a product) instantiate compute<> for that expression type as before.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>

#include "exid/export.hpp"

// Two groups, each compiled in its own file so that a parallel build compiles them side by side
// (eigen_instances_factors.cpp, eigen_instances_spectral.cpp). A class's explicit instantiation
// covers its non-template members; compute<InputType>() is a member template, declared for
// InputType = MatrixXd. The QRs come first: the SVDs' preconditioners use ColPivHouseholderQR.
// Only whole classes and member templates: clang 14 ignores the visibility attribute on an
// explicit instantiation of one member of a class that is not itself instantiated
// (HouseholderQR<Ref<MatrixXd>>::computeInPlace() came out hidden and undefined for the
// libraries that used it), and the ctest unit.eigen_instances checks the exports.
#define EXID_EIGEN_FACTORS(EXTERN)                                                                 \
  EXTERN template class EXID_API Eigen::HouseholderQR<Eigen::MatrixXd>;                            \
  EXTERN template class EXID_API Eigen::ColPivHouseholderQR<Eigen::MatrixXd>;                      \
  EXTERN template class EXID_API Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd>;          \
  EXTERN template class EXID_API Eigen::LDLT<Eigen::MatrixXd>;                                     \
  EXTERN template class EXID_API Eigen::LLT<Eigen::MatrixXd>;                                      \
  EXTERN template class EXID_API Eigen::PartialPivLU<Eigen::MatrixXd>;                             \
  EXTERN template class EXID_API Eigen::FullPivLU<Eigen::MatrixXd>;                                \
  EXTERN template EXID_API Eigen::LDLT<Eigen::MatrixXd>&                                           \
  Eigen::LDLT<Eigen::MatrixXd>::compute<Eigen::MatrixXd>(                                          \
      const Eigen::EigenBase<Eigen::MatrixXd>&);                                                   \
  EXTERN template EXID_API Eigen::LLT<Eigen::MatrixXd>&                                            \
  Eigen::LLT<Eigen::MatrixXd>::compute<Eigen::MatrixXd>(const Eigen::EigenBase<Eigen::MatrixXd>&); \
  EXTERN template EXID_API Eigen::ColPivHouseholderQR<Eigen::MatrixXd>&                            \
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd>::compute<Eigen::MatrixXd>(                           \
      const Eigen::EigenBase<Eigen::MatrixXd>&);                                                   \
  EXTERN template EXID_API Eigen::HouseholderQR<Eigen::MatrixXd>&                                  \
  Eigen::HouseholderQR<Eigen::MatrixXd>::compute<Eigen::MatrixXd>(                                 \
      const Eigen::EigenBase<Eigen::MatrixXd>&);

#define EXID_EIGEN_SPECTRAL(EXTERN)                                              \
  EXTERN template class EXID_API Eigen::JacobiSVD<Eigen::MatrixXd>;              \
  EXTERN template class EXID_API Eigen::BDCSVD<Eigen::MatrixXd>;                 \
  EXTERN template class EXID_API Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>; \
  EXTERN template EXID_API Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>&       \
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>::compute<Eigen::MatrixXd>(      \
      const Eigen::EigenBase<Eigen::MatrixXd>&, int);

#ifdef EXID_EIGEN_DEFINE_FACTORS
EXID_EIGEN_FACTORS()
#else
EXID_EIGEN_FACTORS(extern)
#endif
#ifdef EXID_EIGEN_DEFINE_SPECTRAL
EXID_EIGEN_SPECTRAL()
#else
EXID_EIGEN_SPECTRAL(extern)
#endif
