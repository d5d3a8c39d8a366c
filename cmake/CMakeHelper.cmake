# Helpers that declare procam's libraries and tests (one library per top-level folder).

# procam_add_library(NAME SOURCES... [PUBLIC_LINK libs...] [PRIVATE_LINK libs...])
# Declares the static library `procam_NAME`; includes are rooted at the repository root.
function(procam_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_LINK;PRIVATE_LINK" ${ARGN})
  add_library(procam_${name} STATIC ${ARG_SOURCES})
  target_include_directories(procam_${name} PUBLIC ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR}/include)
  target_link_libraries(procam_${name} PUBLIC ${ARG_PUBLIC_LINK} PRIVATE ${ARG_PRIVATE_LINK})
  # Warnings for C++ sources only (nvcc takes its own flags).
  target_compile_options(procam_${name} PRIVATE "$<$<COMPILE_LANGUAGE:CXX>:${PROCAM_WARNINGS}>")
endfunction()

# procam_add_test(MODULE NAME SOURCES... [LINK libs...])
# Declares the gtest binary `MODULE_NAME_test`, registered with CTest as `MODULE/NAME`.
function(procam_add_test module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LINK" ${ARGN})
  set(target ${module}_${name}_test)
  add_executable(${target} ${ARG_SOURCES})
  target_link_libraries(${target} PRIVATE procam_testing ${ARG_LINK})
  target_compile_options(${target} PRIVATE ${PROCAM_WARNINGS})
  add_test(NAME ${module}/${name} COMMAND ${target})
  set_tests_properties(${module}/${name} PROPERTIES
    ENVIRONMENT "PROCAM_SOURCE_DIR=${PROJECT_SOURCE_DIR};PROCAM_SHARED_DIR=${PROCAM_SHARED_DIR}")
endfunction()
