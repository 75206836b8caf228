# 64-bit Arm Linux (e.g. a Raspberry Pi 4/5 or an i.MX8 running Debian), cross-compiled with
# Debian's gcc-aarch64-linux-gnu. Executables are linked statically so they run on any aarch64
# Linux, and here under qemu-user (qemu-aarch64-static), without an aarch64 root file system.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)

set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_AR aarch64-linux-gnu-ar CACHE FILEPATH "")
set(CMAKE_RANLIB aarch64-linux-gnu-ranlib CACHE FILEPATH "")
set(CMAKE_EXE_LINKER_FLAGS_INIT "-static")

# Libraries and headers come from the cross toolchain's sysroot, programs from the host.
set(CMAKE_FIND_ROOT_PATH /usr/aarch64-linux-gnu)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

# ctest and add_custom_command(... ${CMAKE_CROSSCOMPILING_EMULATOR}) run target programs through it.
find_program(ARM_QEMU_AARCH64 NAMES qemu-aarch64-static qemu-aarch64)
if(ARM_QEMU_AARCH64)
  set(CMAKE_CROSSCOMPILING_EMULATOR "${ARM_QEMU_AARCH64}")
endif()
