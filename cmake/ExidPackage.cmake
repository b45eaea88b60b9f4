# Installation: headers, the core libraries, the exid executable, the plugins (installed by
# exid_add_plugin) and a CMake package so that out-of-tree plugins can do
#   find_package(exid REQUIRED)
#   exid_add_plugin(my_criterion SOURCES my_criterion.cpp)
include(CMakePackageConfigHelpers)

install(DIRECTORY ${PROJECT_SOURCE_DIR}/framework/include/exid DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp")
install(FILES ${CMAKE_BINARY_DIR}/generated/include/exid/version.hpp
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/exid)
set(EXID_EXPORTED_TARGETS exid_dynamics exid_core)
set_target_properties(exid_dynamics PROPERTIES EXPORT_NAME dynamics)   # exid::dynamics
set_target_properties(exid_core PROPERTIES EXPORT_NAME core)           # exid::core
if(TARGET exid_robots)
  list(APPEND EXID_EXPORTED_TARGETS exid_robots)
  set_target_properties(exid_robots PROPERTIES EXPORT_NAME robots)     # exid::robots
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
