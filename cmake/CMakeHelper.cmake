# Helpers that declare procam's libraries and tests (one library per top-level folder).

# procam_add_library(NAME SOURCES... [PUBLIC_LINK libs...] [PRIVATE_LINK libs...])
# Declares the static library `procam_NAME`; includes are rooted at the repository root (in an
# installed tree: include/procam). `cmake --install` installs it with the folder's headers, as
# `procam::NAME` of the CMake package (cmake/procamConfig.cmake.in).
function(procam_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_LINK;PRIVATE_LINK" ${ARGN})
  add_library(procam_${name} STATIC ${ARG_SOURCES})
  add_library(procam::${name} ALIAS procam_${name})
  set_target_properties(procam_${name} PROPERTIES EXPORT_NAME ${name})
  # The Python module (python/) links the libraries into a shared object: their code must be
  # position-independent (-fPIC; Debian's default -fPIE makes thread-local variables that a
  # shared object cannot hold).
  if(PROCAM_WITH_PYTHON)
    set_target_properties(procam_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  endif()
  target_include_directories(procam_${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}> $<BUILD_INTERFACE:${PROJECT_BINARY_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}/procam>)
  install(TARGETS procam_${name} EXPORT procamTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  # A folder's headers once, with its main library (procam_capture, not procam_capture_v4l2).
  get_filename_component(folder ${CMAKE_CURRENT_SOURCE_DIR} NAME)
  if(folder STREQUAL name)
    install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/procam/${folder}
            FILES_MATCHING PATTERN "*.h" PATTERN "*.cuh")
  endif()
  target_link_libraries(procam_${name} PUBLIC ${ARG_PUBLIC_LINK} PRIVATE ${ARG_PRIVATE_LINK})
  # Warnings for C++ sources only (nvcc takes its own flags).
  target_compile_options(procam_${name} PRIVATE "$<$<COMPILE_LANGUAGE:CXX>:${PROCAM_WARNINGS}>")
endfunction()

# procam_add_test(MODULE NAME SOURCES... [LINK libs...] [WRAPPER command...])
# Declares the gtest binary `MODULE_NAME_test`, registered with CTest as `MODULE/NAME`; with
# WRAPPER, CTest runs `command... BINARY` (e.g. scripts/in_private_netns.sh).
function(procam_add_test module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LINK;WRAPPER" ${ARGN})
  set(target ${module}_${name}_test)
  add_executable(${target} ${ARG_SOURCES})
  target_link_libraries(${target} PRIVATE procam_testing ${ARG_LINK})
  target_compile_options(${target} PRIVATE ${PROCAM_WARNINGS})
  if(ARG_WRAPPER)
    add_test(NAME ${module}/${name} COMMAND ${ARG_WRAPPER} $<TARGET_FILE:${target}>)
  else()
    add_test(NAME ${module}/${name} COMMAND ${target})
  endif()
  set_tests_properties(${module}/${name} PROPERTIES
    ENVIRONMENT "PROCAM_SOURCE_DIR=${PROJECT_SOURCE_DIR};PROCAM_SHARED_DIR=${PROCAM_SHARED_DIR}")
endfunction()
