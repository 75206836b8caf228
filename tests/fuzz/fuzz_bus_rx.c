/* libFuzzer: the controller's handling of any received frame (id, flags, length, data), period
 * after period, as arm_bus_handle_rx sees them. No crash, and its counters add up: every frame is
 * counted exactly once, under the kind it was handled as (a miscount traps, a finding). */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "arm/drive_bus.h"

static uint32_t counter_of(const arm_rx_counters_t *c, arm_rx_kind_t kind)
{
    switch (kind) {
    case ARM_RX_STATE: return c->state;
    case ARM_RX_HEARTBEAT: return c->heartbeat;
    case ARM_RX_EMCY: return c->emcy;
    case ARM_RX_FOREIGN_MASTER: return c->foreign_master;
    case ARM_RX_UNKNOWN_ID: return c->unknown_id;
    case ARM_RX_BAD_LENGTH: return c->bad_length;
    case ARM_RX_WRONG_COUNTER: return c->wrong_counter;
    case ARM_RX_BAD_FORMAT: return c->bad_format;
    case ARM_RX_SIM_IDENTITY: return c->sim_identity;
    case ARM_RX_DUPLICATE_STATE: return c->duplicate_state;
    }
    __builtin_trap(); /* a kind the counters do not know */
}

static uint32_t counted(const arm_rx_counters_t *c)
{
    return c->state + c->heartbeat + c->emcy + c->foreign_master + c->unknown_id + c->bad_length +
           c->wrong_counter + c->bad_format + c->sim_identity + c->duplicate_state;
}

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
        const arm_rx_counters_t before = bus.rx;
        const arm_rx_kind_t kind = arm_bus_handle_rx(&bus, &f);
        if (counted(&bus.rx) != counted(&before) + 1u || counter_of(&bus.rx, kind) != counter_of(&before, kind) + 1u)
            __builtin_trap();
#if ARM_N_JOINTS < 32
        if ((bus.fresh_mask >> ARM_N_JOINTS) != 0u) __builtin_trap(); /* a state of a joint the arm has not */
#endif
        if (++handled % 7u == 0u) arm_bus_begin_period(&bus, ++period, &sync);
    }
    if (counted(&bus.rx) != handled) __builtin_trap();
    return 0;
}
