/* libFuzzer: a kernel SocketCAN frame (any bytes, any read size) converted to a frame. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "arm/can_socketcan.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    arm_socketcan_frame_t in;
    memset(&in, 0, sizeof in);
    memcpy(&in, data, size < sizeof in ? size : sizeof in);
    arm_can_frame_t f;
    (void)arm_socketcan_to_frame(&in, size, &f);
    return 0;
}
