// exid — the one instantiation of Eigen's dense decompositions of MatrixXd
// (exid/eigen_instances.hpp): the spectral group.
#define EXID_EIGEN_DEFINE_SPECTRAL
#include "exid/eigen_instances.hpp"
