// exid tests — reference robots built from published tables (see the .cpp for sources).
#pragma once

#include "exid/robot_model.hpp"

namespace exid::testing {

/// PUMA 560, standard DH + Corke/Armstrong parameters (the published PUMA 560 reference parameters,
/// from RTB mdl_puma560.m). Drives: Ia = Jm G^2, Fv = B G^2, Fc = Tc+ |G| (link side).
RobotModel puma560Standard();
/// PUMA 560, modified DH, Armstrong-Khatib-Burdick 1986 parameters (RTB mdl_puma560akb.m).
RobotModel puma560Akb();
/// Franka Emika Panda, modified DH, Gaz et al. RA-L 2019 feasible parameters; sensor at the flange.
RobotModel panda();
/// Planar 2R arm (standard DH, a1 = 1, a2 = 0.8), joints about z, gravity -9.81 y (in the plane)
/// when vertical, along -z (normal to the plane) otherwise.
RobotModel planar2R(bool vertical);

}  // namespace exid::testing
