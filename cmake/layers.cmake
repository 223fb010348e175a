# vofusion_layer(<name> [<layer below> ...]): the static library vofusion_<name> from src/<name>/*.cpp,
# linked to the layers named, and a build step that refuses any "vofusion/<other>/..." include in
# src/<name>/ or include/vofusion/<name>/ whose layer is not <name> or below it.
function(vofusion_layer name)
  set(allowed ${name})
  foreach(below ${ARGN})
    get_property(below_allowed GLOBAL PROPERTY VOFUSION_LAYER_${below}_ALLOWED)
    if(NOT below_allowed)
      message(FATAL_ERROR "vofusion_layer(${name}): layer '${below}' must be declared before it")
    endif()
    list(APPEND allowed ${below_allowed})
  endforeach()
  list(REMOVE_DUPLICATES allowed)
  set_property(GLOBAL PROPERTY VOFUSION_LAYER_${name}_ALLOWED ${allowed})
  set_property(GLOBAL APPEND PROPERTY VOFUSION_LAYERS ${name})

  set(dirs ${CMAKE_SOURCE_DIR}/src/${name} ${CMAKE_SOURCE_DIR}/include/vofusion/${name})
  file(GLOB sources CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/src/${name}/*.cpp)
  file(GLOB_RECURSE checked CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/src/${name}/*.cpp ${CMAKE_SOURCE_DIR}/src/${name}/*.h
       ${CMAKE_SOURCE_DIR}/include/vofusion/${name}/*.h)
  add_library(vofusion_${name} STATIC ${sources})
  target_link_libraries(vofusion_${name} PUBLIC vofusion_deps)
  foreach(below ${ARGN})
    target_link_libraries(vofusion_${name} PUBLIC vofusion_${below})
  endforeach()

  string(REPLACE ";" "," allowed_csv "${allowed}")
  string(REPLACE ";" "," dirs_csv "${dirs}")
  set(stamp ${CMAKE_BINARY_DIR}/layers/${name}.checked)
  add_custom_command(OUTPUT ${stamp}
    COMMAND ${CMAKE_COMMAND} -DLAYER=${name} -DALLOWED=${allowed_csv} -DDIRS=${dirs_csv} -DSTAMP=${stamp}
            -P ${CMAKE_SOURCE_DIR}/cmake/check_layer.cmake
    DEPENDS ${checked} ${CMAKE_SOURCE_DIR}/cmake/check_layer.cmake
    COMMENT "Checking that layer ${name} includes only ${allowed}" VERBATIM)
  add_custom_target(vofusion_${name}_includes DEPENDS ${stamp})
  add_dependencies(vofusion_${name} vofusion_${name}_includes)
endfunction()
