# Cortex-M4F: single-precision FPU (FPv4-SP-D16), hard-float ABI. QEMU board: mps2-an386.
set(ARM_MCU_FLAGS "-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard")
set(ARM_MCU cortex-m4)
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
