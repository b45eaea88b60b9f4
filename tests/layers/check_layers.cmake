# unit.layers (docs/architecture.md, "Layers"): with the usage requirements of the `data` layer,
# a file including a header of the `study` layer above it does not compile, for that include,
# and one including headers of its own and lower layers does.
#   cmake -DBIN=<build dir> -P check_layers.cmake
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BIN} --target exid_layer_probe_down
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "the downward probe (data including base and data) does not build:\n${out}${err}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BIN} --target exid_layer_probe_up
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(rc EQUAL 0)
  message(FATAL_ERROR "an upward include (data including exid/runner.hpp of study) compiled")
endif()
if(NOT "${out}${err}" MATCHES "exid/runner.hpp")
  message(FATAL_ERROR "the upward probe failed, but not for its include:\n${out}${err}")
endif()
message(STATUS "layers: the upward include fails for exid/runner.hpp; the downward one builds")
