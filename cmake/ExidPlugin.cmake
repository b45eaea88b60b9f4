# exid_add_plugin(NAME SOURCES... [LIBRARIES libs...])
# Builds one plugin library (MODULE) named exid_plugin_<NAME>, with hidden symbols except the
# manifest entry point, into the plugin directory of the build tree, and installs it.
# Works in this tree and, through find_package(exid), in out-of-tree projects.
function(exid_add_plugin name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBRARIES" ${ARGN})
  set(sources ${ARG_SOURCES} ${ARG_UNPARSED_ARGUMENTS})
  set(target exid_plugin_${name})
  add_library(${target} MODULE ${sources})
  set_property(GLOBAL APPEND PROPERTY EXID_PLUGIN_TARGETS ${target})
  if(TARGET exid::core)
    target_link_libraries(${target} PRIVATE exid::core ${ARG_LIBRARIES})
  else()
    target_link_libraries(${target} PRIVATE exid_core ${ARG_LIBRARIES})
  endif()
  if(TARGET fmt::fmt)
    target_link_libraries(${target} PRIVATE fmt::fmt)
  endif()
  set_target_properties(${target} PROPERTIES
    PREFIX "lib"
    CXX_VISIBILITY_PRESET hidden
    VISIBILITY_INLINES_HIDDEN ON)
  if(DEFINED EXID_PLUGIN_BUILD_DIR)
    set_target_properties(${target} PROPERTIES LIBRARY_OUTPUT_DIRECTORY ${EXID_PLUGIN_BUILD_DIR})
  endif()
  if(COMMAND exid_warnings)
    exid_warnings(${target})
  endif()
  if(DEFINED EXID_PLUGIN_INSTALL_DIR)
    install(TARGETS ${target} LIBRARY DESTINATION ${EXID_PLUGIN_INSTALL_DIR})
  endif()
endfunction()
