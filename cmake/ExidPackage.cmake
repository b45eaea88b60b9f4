# Installation: headers, the core libraries, the exid executable, the plugins (installed by
# exid_add_plugin) and a CMake package so that out-of-tree plugins can do
#   find_package(exid REQUIRED)
#   exid_add_plugin(my_criterion SOURCES my_criterion.cpp)
include(CMakePackageConfigHelpers)

# The public headers: each layer's include/ (docs/architecture.md, "Layers"); a layer's
# internal/ and the headers beside its sources are not installed.
foreach(layer ${EXID_PUBLIC_LAYERS})
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/framework/${layer}/include/exid
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} FILES_MATCHING PATTERN "*.hpp")
endforeach()
install(FILES ${CMAKE_BINARY_DIR}/generated/include/exid/version.hpp
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid)
set(EXID_EXPORTED_TARGETS exid_dynamics exid_core)
set_target_properties(exid_dynamics PROPERTIES EXPORT_NAME dynamics)   # exid::dynamics
set_target_properties(exid_core PROPERTIES EXPORT_NAME core)           # exid::core
if(TARGET exid_robots)
  list(APPEND EXID_EXPORTED_TARGETS exid_robots)
  set_target_properties(exid_robots PROPERTIES EXPORT_NAME robots)     # exid::robots
endif()
# The helpers each plugin kind shares, so that an out-of-tree plugin links them instead of
# copying them: least-squares accumulation, signals and streaming (exid::estimators_common,
# <exid/estimators/...>), model helpers ("model_common.hpp", exid::models_common), optimiser
# limits, budgets, tracker, starts and L-BFGS ("optim_common.hpp", exid::optimizers_common),
# trajectory helpers ("traj_common.hpp", exid::trajectories_common), the criteria's spectrum and
# SpectralCriterion ("spectrum.hpp", exid::criteria_common).
if(TARGET exid_estimators_common)
  list(APPEND EXID_EXPORTED_TARGETS exid_estimators_common)
  set_target_properties(exid_estimators_common PROPERTIES EXPORT_NAME estimators_common)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/estimators/common/include/exid/estimators
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid FILES_MATCHING PATTERN "*.hpp")
endif()
if(TARGET exid_models_common)
  list(APPEND EXID_EXPORTED_TARGETS exid_models_common)
  set_target_properties(exid_models_common PROPERTIES EXPORT_NAME models_common)
  install(FILES ${PROJECT_SOURCE_DIR}/models/common/model_common.hpp
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid/models)
endif()
if(TARGET exid_optim_common)
  list(APPEND EXID_EXPORTED_TARGETS exid_optim_common)
  set_target_properties(exid_optim_common PROPERTIES EXPORT_NAME optimizers_common)
  install(FILES ${PROJECT_SOURCE_DIR}/optimizers/common/optim_common.hpp
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid/optimizers)
endif()
if(TARGET exid_trajectory_common)
  list(APPEND EXID_EXPORTED_TARGETS exid_trajectory_common)
  set_target_properties(exid_trajectory_common PROPERTIES EXPORT_NAME trajectories_common)
  install(FILES ${PROJECT_SOURCE_DIR}/trajectories/common/traj_common.hpp
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid/trajectories)
endif()
if(TARGET exid_criteria_common)
  list(APPEND EXID_EXPORTED_TARGETS exid_criteria_common)
  set_target_properties(exid_criteria_common PROPERTIES EXPORT_NAME criteria_common)
  install(FILES ${PROJECT_SOURCE_DIR}/criteria/common/spectrum.hpp
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid/criteria)
endif()
install(TARGETS ${EXID_EXPORTED_TARGETS} EXPORT exidTargets
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(TARGETS exid RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(EXPORT exidTargets NAMESPACE exid:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/exid)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/exidConfig.cmake.in
  ${CMAKE_BINARY_DIR}/exidConfig.cmake INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/exid)
write_basic_package_version_file(${CMAKE_BINARY_DIR}/exidConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/exidConfig.cmake ${CMAKE_BINARY_DIR}/exidConfigVersion.cmake
        ${PROJECT_SOURCE_DIR}/cmake/ExidPlugin.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/exid)

# A Debian package a packager can use: `cpack -G DEB` in the build tree (after a Release build)
# writes exid_<version>_<arch>.deb with the program, libraries, plugins, headers and the CMake
# package, installed under /usr (plugins in /usr/lib/exid/plugins, found next to libexid_core).
# Runtime dependencies come from dpkg-shlibdeps; the headers need Eigen and fmt to be used.
set(CPACK_PACKAGE_NAME exid)
set(CPACK_PACKAGE_VENDOR "The exid developers")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_RESOURCE_FILE_LICENSE ${PROJECT_SOURCE_DIR}/LICENSE)
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "The exid developers")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "libeigen3-dev (>= 3.4), libfmt-dev, cmake (>= ${EXID_CMAKE_MINIMUM})")
if(EXID_WITH_PYTHON)
  # The Python package (/usr/lib/python3/dist-packages/exid): its module is built for this
  # Python minor version; pandas is needed by exid.read_matrix alone.
  math(EXPR exid_python_next_minor "${Python3_VERSION_MINOR} + 1")
  string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS
         ", python3 (>= ${Python3_VERSION_MAJOR}.${Python3_VERSION_MINOR})"
         ", python3 (<< ${Python3_VERSION_MAJOR}.${exid_python_next_minor}), python3-numpy")
  set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "python3-pandas")
endif()
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "Experimental identification of robot and payload dynamics, and excitation design.\n exid identifies robot and payload dynamic parameters from recordings or simulations and\n designs the exciting trajectories that make the identification well conditioned. Studies\n are YAML files; robots, models, criteria, optimisers, experiments and estimators are\n plugins.")
install(FILES ${PROJECT_SOURCE_DIR}/LICENSE ${PROJECT_SOURCE_DIR}/README.md
        DESTINATION ${CMAKE_INSTALL_DOCDIR})
include(CPack)
