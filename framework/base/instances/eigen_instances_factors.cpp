// exid — the one instantiation of Eigen's dense decompositions of MatrixXd
// (exid/eigen_instances.hpp): the factors group.
#define EXID_EIGEN_DEFINE_FACTORS
#include "exid/eigen_instances.hpp"
