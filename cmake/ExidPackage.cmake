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
# Forwarding headers for one release (0.3): the 0.2 headers of the study, the matrix and the
# inspection are no longer installed (framework/compat/exid says where their public parts went).
install(DIRECTORY ${PROJECT_SOURCE_DIR}/framework/compat/exid
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} FILES_MATCHING PATTERN "*.hpp")
set(EXID_EXPORTED_TARGETS exid_dynamics exid_core)
set_target_properties(exid_dynamics PROPERTIES EXPORT_NAME dynamics)   # exid::dynamics
set_target_properties(exid_core PROPERTIES EXPORT_NAME core)           # exid::core
if(TARGET exid_robots)
  list(APPEND EXID_EXPORTED_TARGETS exid_robots)
  set_target_properties(exid_robots PROPERTIES EXPORT_NAME robots)     # exid::robots
endif()
# The helpers each plugin kind shares, so that an out-of-tree plugin links them instead of
# copying them, one convention for every kind: <kind>/common/include/exid/<kind>/*.hpp installed
# as <exid/<kind>/...>, the library exid_<kind>_common exported as exid::<kind>_common.
# Least-squares accumulation, signals and streaming (exid::estimators_common,
# "exid/estimators/..."), model helpers (exid::models_common, "exid/models/model_common.hpp"),
# optimiser limits, budgets, tracker, starts and L-BFGS (exid::optimizers_common,
# "exid/optimizers/optim_common.hpp"), trajectory helpers (exid::trajectories_common,
# "exid/trajectories/traj_common.hpp"), the criteria's spectrum and SpectralCriterion
# (exid::criteria_common, "exid/criteria/spectrum.hpp").
foreach(kind estimators models optimizers trajectories criteria)
  if(TARGET exid_${kind}_common)
    list(APPEND EXID_EXPORTED_TARGETS exid_${kind}_common)
    set_target_properties(exid_${kind}_common PROPERTIES EXPORT_NAME ${kind}_common)
    install(DIRECTORY ${PROJECT_SOURCE_DIR}/${kind}/common/include/exid/${kind}
            DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid FILES_MATCHING PATTERN "*.hpp")
  endif()
endforeach()
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
# The examples (studies, matrices, the notebook) and the data sets they read, laid out as in the
# source tree under <prefix>/share/exid beside robots/ (whose description files robots/ installs;
# the extra files such as robots/tx40/tx40_exid.xml here): a study's relative paths keep working,
# and the Python package finds them (exid.data_path).
install(DIRECTORY ${PROJECT_SOURCE_DIR}/examples ${PROJECT_SOURCE_DIR}/data
        DESTINATION ${CMAKE_INSTALL_DATADIR}/exid)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/robots/ DESTINATION ${CMAKE_INSTALL_DATADIR}/exid/robots
        FILES_MATCHING PATTERN "*.xml")
include(CPack)
