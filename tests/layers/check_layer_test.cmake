# cmake -DCHECK=<cmake/check_layer.cmake> -DALLOWED=<fusion's allowed layers> -DFIXTURES=<tests/layers>
#       -DEXPECT=refused|accepted -DFIXTURE=<folder> -P check_layer_test.cmake
# Runs the layer check on a fixture folder as layer "fusion" and fails unless it is refused (non-zero
# exit, naming the file and the layer it reached) or accepted, as EXPECT says.
cmake_minimum_required(VERSION 3.16)
execute_process(COMMAND ${CMAKE_COMMAND} -DLAYER=fusion -DALLOWED=${ALLOWED} -DDIRS=${FIXTURES}/${FIXTURE} -P ${CHECK}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${err}")
if(EXPECT STREQUAL "refused")
  if(rc EQUAL 0)
    message(FATAL_ERROR "the layer check accepted fusion including pipeline")
  endif()
  if(NOT err MATCHES "upward.h: includes vofusion/pipeline/reconstruction.h: fusion may not include pipeline")
    message(FATAL_ERROR "the refusal does not name the file, the include and the layer")
  endif()
elseif(NOT rc EQUAL 0)
  message(FATAL_ERROR "the layer check refused includes of layers below fusion")
endif()
