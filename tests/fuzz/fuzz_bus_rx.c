/* libFuzzer: the controller's handling of any received frame (id, flags, length, data), period
 * after period, as arm_bus_handle_rx sees them. No crash, and its counters add up. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "arm/drive_bus.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static arm_drive_bus_t bus;
    arm_bus_init(&bus);
    arm_can_frame_t sync;
    uint32_t period = 0u;
    arm_bus_begin_period(&bus, period, &sync);
    unsigned handled = 0u;
    /* each frame: 2 bytes id, 1 flags, 1 length, then up to 64 data bytes */
    while (size >= 4u) {
        arm_can_frame_t f;
        memset(&f, 0, sizeof f);
        f.id = (uint32_t)(data[0] | (data[1] << 8)) & 0x7FFu;
        f.flags = data[2];
        f.len = data[3];
        data += 4;
        size -= 4;
        const size_t n = f.len < sizeof f.data ? f.len : sizeof f.data;
        const size_t take = n < size ? n : size;
        memcpy(f.data, data, take);
        data += take;
        size -= take;
        (void)arm_bus_handle_rx(&bus, &f);
        if (++handled % 7u == 0u) arm_bus_begin_period(&bus, ++period, &sync);
    }
    return 0;
}
