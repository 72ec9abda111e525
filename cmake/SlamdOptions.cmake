# Compiler warnings as an interface target every slamd target links privately.
add_library(slamd_warnings INTERFACE)
add_library(slamd::warnings ALIAS slamd_warnings)
target_compile_options(slamd_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wold-style-cast -Wcast-align
  -Woverloaded-virtual -Wnull-dereference -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough)
# CI builds with -DSLAMD_WERROR=ON (`make test WERROR=ON` in .ci/run): a warning fails the build.
option(SLAMD_WERROR "Treat compiler warnings in slamd's own code as errors" OFF)
if(SLAMD_WERROR)
  target_compile_options(slamd_warnings INTERFACE -Werror)
endif()

# Sanitizers apply to everything built in this tree (libraries, tests, programs) so that a
# sanitized test never links an unsanitized slamd library.
if(SLAMD_SANITIZE)
  if(SLAMD_SANITIZE STREQUAL "address")
    set(_slamd_san_flags -fsanitize=address -fno-omit-frame-pointer)
  elseif(SLAMD_SANITIZE STREQUAL "thread")
    set(_slamd_san_flags -fsanitize=thread)
  elseif(SLAMD_SANITIZE STREQUAL "undefined")
    set(_slamd_san_flags -fsanitize=undefined -fno-sanitize-recover=undefined)
  elseif(SLAMD_SANITIZE STREQUAL "address+undefined")
    # One build for both: cheaper than two (CI's time budget), and they do not conflict. The vptr
    # check is off: LCM's own header (lcm-cpp-impl.hpp) hands its subscription objects through
    # void* in a way GCC's check reports on every message received, and GCC cannot exempt one
    # header; slamd downcasts only with dynamic_cast, which checks itself.
    set(_slamd_san_flags -fsanitize=address,undefined -fno-sanitize=vptr
                         -fno-sanitize-recover=undefined -fno-omit-frame-pointer)
  elseif(SLAMD_SANITIZE STREQUAL "fuzzer")
    # The `make fuzz` tree: libFuzzer's coverage instrumentation everywhere (the fuzz programs
    # add -fsanitize=fuzzer for libFuzzer's main), with ASan and UBSan to turn bad reads, leaks
    # and undefined behaviour into findings. libFuzzer comes with clang only.
    if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
      message(FATAL_ERROR "SLAMD_SANITIZE=fuzzer needs clang (CXX=clang++): libFuzzer is clang's")
    endif()
    set(_slamd_san_flags -fsanitize=fuzzer-no-link,address,undefined
                         -fno-sanitize-recover=undefined -fno-omit-frame-pointer)
  else()
    message(FATAL_ERROR "SLAMD_SANITIZE='${SLAMD_SANITIZE}': allowed values are address, thread, "
                        "undefined, address+undefined, fuzzer")
  endif()
  # -g1: line tables only, all a sanitizer report needs for file:line in its stacks, and a
  # quarter less compile time than full debug info (no variable or type information).
  add_compile_options(${_slamd_san_flags} -g1)
  add_link_options(${_slamd_san_flags})
  # Optimised (-O2, the -g from RelWithDebInfo lowered by the -g1 above): sanitized runs of the
  # suite stay fast enough.
  if(CMAKE_BUILD_TYPE STREQUAL "Release")
    set(CMAKE_BUILD_TYPE RelWithDebInfo CACHE STRING "Build type" FORCE)
  endif()
endif()

# Eigen: catch uninitialised matrices in debug builds (basalt's practice).
add_compile_definitions($<$<CONFIG:Debug>:EIGEN_INITIALIZE_MATRICES_BY_NAN>)

# slamd_add_library(<area> SOURCES ... DEPS ...): the library slamd_<area>, alias slamd::<area>.
function(slamd_add_library area)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(slamd_${area} STATIC ${ARG_SOURCES})
  add_library(slamd::${area} ALIAS slamd_${area})
  target_include_directories(slamd_${area} PUBLIC ${PROJECT_SOURCE_DIR}/include)
  target_link_libraries(slamd_${area} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS} slamd::warnings)
  set_target_properties(slamd_${area} PROPERTIES POSITION_INDEPENDENT_CODE ON)
endfunction()

# slamd_add_program(<name> SOURCES ... DEPS ...): an executable in build/bin.
function(slamd_add_program name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} slamd::warnings)
endfunction()

# slamd_add_program_folders(): every subfolder of the current folder that has a CMakeLists.txt is
# one program (or benchmark) and joins the build, unless it names an area left out with
# SLAMD_SKIP_AREAS (bench/<area>, tools/slamd-<area>). Used by tools/, clients/ and bench/.
function(slamd_add_program_folders)
  file(GLOB children LIST_DIRECTORIES true RELATIVE ${CMAKE_CURRENT_SOURCE_DIR}
       ${CMAKE_CURRENT_SOURCE_DIR}/*)
  list(SORT children)
  foreach(child IN LISTS children)
    if(NOT IS_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/${child}
       OR NOT EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/${child}/CMakeLists.txt)
      continue()
    endif()
    set(skip FALSE)
    foreach(area IN LISTS SLAMD_SKIP_AREAS)
      if(child STREQUAL area OR child STREQUAL "slamd-${area}")
        set(skip TRUE)
      endif()
    endforeach()
    if(NOT skip)
      add_subdirectory(${child})
    endif()
  endforeach()
endfunction()
