# Cortex-M3: no FPU. The core is float32 throughout (RNEA, reference, safety layer), so here it
# runs on newlib's software floating point (-mfloat-abi=soft): correct, and slow. A fixed-point
# build of the whole core is the lead's later work. QEMU board: mps2-an385.
set(ARM_MCU_FLAGS "-mcpu=cortex-m3 -mthumb -mfloat-abi=soft")
set(ARM_MCU cortex-m3)
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
