# Bare-metal Cortex-M with Debian's gcc-arm-none-eabi and newlib-nano (libnewlib-arm-none-eabi).
# Included by the per-core files (cortex-m3/m4/m7.cmake), which set ARM_MCU_FLAGS first.
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)

set(CMAKE_C_COMPILER arm-none-eabi-gcc)
set(CMAKE_ASM_COMPILER arm-none-eabi-gcc)
set(CMAKE_AR arm-none-eabi-ar CACHE FILEPATH "")
set(CMAKE_RANLIB arm-none-eabi-ranlib CACHE FILEPATH "")
set(CMAKE_OBJCOPY arm-none-eabi-objcopy CACHE FILEPATH "")
set(CMAKE_OBJDUMP arm-none-eabi-objdump CACHE FILEPATH "")
set(CMAKE_SIZE arm-none-eabi-size CACHE FILEPATH "")
# No OS to link a test executable against during compiler checks.
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

# -ffunction-sections/-fdata-sections + --gc-sections drop what the image does not call.
# -fstack-usage feeds the worst-case stack check (firmware/port/cortex_m/stack_usage.py).
set(CMAKE_C_FLAGS_INIT
    "${ARM_MCU_FLAGS} -ffunction-sections -fdata-sections -fno-common -fstack-usage")
set(CMAKE_ASM_FLAGS_INIT "${ARM_MCU_FLAGS}")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${ARM_MCU_FLAGS} --specs=nano.specs --specs=nosys.specs -nostartfiles -Wl,--gc-sections")

set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
