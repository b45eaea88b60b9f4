cmake_policy(SET CMP0057 NEW)  # if(... IN_LIST ...)
# ctest unit.eigen_instances: Eigen's dense decompositions of MatrixXd are compiled once
# (exid/eigen_instances.hpp) and stay so.
#  1. No source of the project includes <Eigen/SVD>, <Eigen/QR>, <Eigen/Cholesky>, <Eigen/LU>,
#     <Eigen/Eigenvalues>, <Eigen/Householder> or <Eigen/Dense> itself: it includes
#     exid/eigen_instances.hpp, which declares the instantiations (a file that included Eigen's
#     header alone would compile the decompositions again, silently).
#  2. libexid_dynamics exports each decomposition's factorisation, so that any library or plugin
#     built against exid can use them.
#  3. A source that factors a MatrixXd (the dynamics layer's base_parameters.cpp: HouseholderQR,
#     ColPivHouseholderQR) does not define the factorisation itself.
# Usage: cmake -DSOURCE_DIR=<root> -DNM=<nm> -DLIBRARY=<libexid_dynamics> -DOBJECTS=<objects;...>
#        -P ExidCheckEigenInstances.cmake
set(bad "")
foreach(dir framework estimators models criteria optimizers trajectories experiments robots tests
            python benchmarks)
  file(GLOB_RECURSE sources ${SOURCE_DIR}/${dir}/*.cpp ${SOURCE_DIR}/${dir}/*.hpp)
  foreach(src ${sources})
    if(src MATCHES "/exid/eigen_instances\\.hpp$")
      continue()
    endif()
    file(STRINGS ${src} lines REGEX "^[ \t]*#[ \t]*include[ \t]*<Eigen/(SVD|QR|Cholesky|LU|Eigenvalues|Householder|Dense)>")
    if(lines)
      file(RELATIVE_PATH rel ${SOURCE_DIR} ${src})
      string(APPEND bad "  ${rel}: ${lines}\n")
    endif()
  endforeach()
endforeach()
if(bad)
  message(FATAL_ERROR "these files include Eigen's decompositions without exid/eigen_instances.hpp "
                      "(include it instead):\n${bad}")
endif()

function(defined_symbols file out)
  execute_process(COMMAND ${NM} -C --defined-only ${ARGN} ${file} OUTPUT_VARIABLE text
                  RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${NM} failed on ${file}")
  endif()
  # compared without spaces: demanglers differ in "> >" and "const&"
  string(REPLACE " " "" text "${text}")
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

# the factorisations, as nm -C names them (spaces aside)
set(M "Eigen::Matrix<double, -1, -1, 0, -1, -1>")
set(wanted
  "Eigen::HouseholderQR<${M}>::computeInPlace()"
  "Eigen::ColPivHouseholderQR<${M}>::computeInPlace()"
  "Eigen::CompleteOrthogonalDecomposition<${M}>::computeInPlace()"
  "Eigen::PartialPivLU<${M}>::compute()"
  "Eigen::FullPivLU<${M}>::computeInPlace()"
  "Eigen::JacobiSVD<${M}, 2>::compute(${M} const&, unsigned int)"
  "Eigen::BDCSVD<${M}>::compute(${M} const&, unsigned int)"
  "Eigen::SelfAdjointEigenSolver<${M}>& Eigen::SelfAdjointEigenSolver<${M}>::compute<${M}>(Eigen::EigenBase<${M}> const&, int)"
  "Eigen::LDLT<${M}, 1>& Eigen::LDLT<${M}, 1>::compute<${M}>(Eigen::EigenBase<${M}> const&)"
  "Eigen::LLT<${M}, 1>& Eigen::LLT<${M}, 1>::compute<${M}>(Eigen::EigenBase<${M}> const&)")
defined_symbols(${LIBRARY} exported -D)
set(missing "")
foreach(sym ${wanted})
  string(REPLACE " " "" key "${sym}")
  string(FIND "${exported}" "${key}\n" at)
  if(at EQUAL -1)
    string(APPEND missing "  ${sym}\n")
  endif()
endforeach()
if(missing)
  message(FATAL_ERROR "${LIBRARY} does not export:\n${missing}")
endif()

set(object "")
foreach(obj ${OBJECTS})
  if(obj MATCHES "base_parameters\\.cpp\\.o(bj)?$")
    set(object ${obj})
  endif()
endforeach()
if(NOT object)
  message(FATAL_ERROR "no base_parameters object among ${OBJECTS}")
endif()
defined_symbols(${object} own)
foreach(sym "Eigen::HouseholderQR<${M}>::computeInPlace()"
            "Eigen::ColPivHouseholderQR<${M}>::computeInPlace()")
  string(REPLACE " " "" key "${sym}")
  string(FIND "${own}" "${key}\n" at)
  if(NOT at EQUAL -1)
    message(FATAL_ERROR "${object} compiles ${sym} again (it should use the instantiation "
                        "exid/eigen_instances.hpp declares)")
  endif()
endforeach()
list(LENGTH wanted n)
message(STATUS "no source includes Eigen's decompositions alone; libexid_dynamics exports ${n} "
               "factorisations; base_parameters.cpp uses them")
