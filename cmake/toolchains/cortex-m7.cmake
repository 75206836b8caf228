# Cortex-M7 with the double-precision FPU (FPv5-D16), hard-float ABI. QEMU board: mps2-an500.
set(ARM_MCU_FLAGS "-mcpu=cortex-m7 -mthumb -mfpu=fpv5-d16 -mfloat-abi=hard")
set(ARM_MCU cortex-m7)
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
