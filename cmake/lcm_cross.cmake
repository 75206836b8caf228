# LCM for a cross-compiled Linux controller (aarch64): liblcm's C library compiled from Debian's
# lcm source for the target and linked statically with the target's glib (static archives from
# Debian's arm64 packages). cmake/fetch_aarch64_deps.py fetches both, at configure time, into
# ARM_CROSS_DEPS_DIR (see its docstring for why this route).
#
# Defines: arm_lcm_cross (static library target; link it), ARM_LCM_INCLUDE (lcm/lcm.h lives there).

set(ARM_CROSS_DEPS_DIR "${CMAKE_SOURCE_DIR}/build/deps/${CMAKE_SYSTEM_PROCESSOR}" CACHE PATH
    "Where cmake/fetch_aarch64_deps.py puts the target's LCM source and glib")
if(NOT EXISTS "${ARM_CROSS_DEPS_DIR}/fetched.json")
  message(STATUS "fetching the ${CMAKE_SYSTEM_PROCESSOR} LCM source and glib from Debian into ${ARM_CROSS_DEPS_DIR}")
  execute_process(
    COMMAND "${ARM_PYTHON}" "${CMAKE_SOURCE_DIR}/cmake/fetch_aarch64_deps.py" --out "${ARM_CROSS_DEPS_DIR}"
    RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "could not fetch the ${CMAKE_SYSTEM_PROCESSOR} LCM dependencies (see above): "
                        "they come from Debian's archive through apt-get")
  endif()
endif()

set(_lcm_src "${ARM_CROSS_DEPS_DIR}/lcm-src")
set(_sysroot "${ARM_CROSS_DEPS_DIR}/sysroot")
if(CMAKE_SYSTEM_PROCESSOR STREQUAL "aarch64")
  set(_triplet aarch64-linux-gnu)
else()
  message(FATAL_ERROR "lcm_cross.cmake: no Debian multiarch triplet known for ${CMAKE_SYSTEM_PROCESSOR}")
endif()
set(_libdir "${_sysroot}/usr/lib/${_triplet}")
foreach(f "${_lcm_src}/lcm/lcm.c" "${_libdir}/libglib-2.0.a" "${_libdir}/libpcre2-8.a"
          "${_libdir}/glib-2.0/include/glibconfig.h")
  if(NOT EXISTS "${f}")
    message(FATAL_ERROR "lcm_cross.cmake: ${f} is missing; delete ${ARM_CROSS_DEPS_DIR} and configure again")
  endif()
endforeach()

file(GLOB _lcm_c "${_lcm_src}/lcm/*.c" "${_lcm_src}/lcm/lcmtypes/*.c")
add_library(arm_lcm_cross STATIC ${_lcm_c})
# Third-party code: its own dialect (gnu99, glib's deprecated mutex API), no warnings of ours.
set_target_properties(arm_lcm_cross PROPERTIES C_STANDARD 99 C_EXTENSIONS ON)
target_compile_options(arm_lcm_cross PRIVATE -w)
target_compile_definitions(arm_lcm_cross PRIVATE _GNU_SOURCE)
target_include_directories(arm_lcm_cross PRIVATE "${_lcm_src}" "${_lcm_src}/lcm"
                           "${_sysroot}/usr/include/glib-2.0" "${_libdir}/glib-2.0/include")
target_include_directories(arm_lcm_cross SYSTEM INTERFACE "${_lcm_src}")
target_link_libraries(arm_lcm_cross INTERFACE "${_libdir}/libglib-2.0.a" "${_libdir}/libpcre2-8.a" pthread)
set(ARM_LCM_INCLUDE "${_lcm_src}")
