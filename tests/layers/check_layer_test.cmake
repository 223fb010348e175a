# cmake -DCHECK=<cmake/check_layer.cmake> -DLAYER=<layer> -DALLOWED=<its allowed layers> -DFIXTURES=<tests/layers>
#       -DEXPECT=refused|accepted -DFIXTURE=<folder> [-DREFUSAL=<what the refusal must say>] -P check_layer_test.cmake
# Runs the layer check on a fixture folder as layer LAYER and fails unless it is refused (non-zero exit,
# naming the file, the include and the layer it reached: REFUSAL) or accepted, as EXPECT says.
cmake_minimum_required(VERSION 3.16)
execute_process(COMMAND ${CMAKE_COMMAND} -DLAYER=${LAYER} -DALLOWED=${ALLOWED} -DDIRS=${FIXTURES}/${FIXTURE} -P ${CHECK}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${err}")
if(EXPECT STREQUAL "refused")
  if(rc EQUAL 0)
    message(FATAL_ERROR "the layer check accepted ${FIXTURE}")
  endif()
  if(NOT err MATCHES "${REFUSAL}")
    message(FATAL_ERROR "the refusal does not name the file, the include and the layer (${REFUSAL})")
  endif()
elseif(NOT rc EQUAL 0)
  message(FATAL_ERROR "the layer check refused includes of layers below ${LAYER}")
endif()
