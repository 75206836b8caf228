/* libFuzzer: the CANopen master's boot configurator (firmware/canopen) against a drive that answers
 * anything. Each 6-byte record answers the master's latest SDO request: a correct answer with a
 * fuzzed value, a fuzzed frame on the node's SDO id, silence until the timeout, or a foreign frame;
 * so the walk reaches every step of the sequence (segmented answers, aborts, resets, retries).
 * No crash, no overrun, the log bounded, a failure always named. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "arm/co_boot.h"
#include "arm/co_pdo.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static arm_co_boot_config_t cfg;
    static arm_co_boot_t b;
    arm_co_boot_default_config(&cfg);
    cfg.n_nodes = 2u;
    cfg.node[0] = (arm_co_node_config_t){.node_id = 1u, .joint_torque_limit_nm = 150.0f, .gear_efficiency = 0.9f};
    cfg.node[1] = (arm_co_node_config_t){.node_id = 2u, .expect = ARM_CO_EXPECT_RATED, .rated_torque = 28000u,
                                         .vendor_id = 7u};
    cfg.fault_reset = 1u;
    cfg.sdo_tries = 2u;
    if (arm_co_boot_init(&b, &cfg, 0u) != 0) abort();
    uint64_t now = 0u;
    arm_can_frame_t last[2] = {{0}, {0}};
    int rc = 1;
    while (size >= 6u && rc == 1) {
        rc = arm_co_boot_step(&b, now);
        arm_can_frame_t tx;
        while (arm_co_boot_take_tx(&b, &tx)) {
            if (tx.id == ARM_CO_COB_SDO_RX + 1u || tx.id == ARM_CO_COB_SDO_RX + 2u) last[tx.id - ARM_CO_COB_SDO_RX - 1u] = tx;
        }
        const uint8_t node = (uint8_t)(1u + (data[0] & 1u));
        const arm_can_frame_t *req = &last[node - 1u];
        arm_can_frame_t f = {.id = ARM_CO_COB_SDO_TX + node, .len = 8u};
        switch ((data[0] >> 1) & 3u) {
        case 0: /* the right answer, value fuzzed */
            f.data[0] = (req->data[0] >> 5) == 2u ? (uint8_t)(0x43u | (data[1] & 0x0Cu)) : 0x60u;
            memcpy(&f.data[1], &req->data[1], 3u);
            memcpy(&f.data[4], &data[2], 4u);
            break;
        case 1: /* anything on the node's SDO id */
            memcpy(f.data, &data[1], 5u);
            f.len = (uint8_t)(data[0] >> 3);
            break;
        case 2: /* silence: the request times out */
            now += cfg.sdo_timeout_us;
            f.id = 0u;
            break;
        default: /* another node's frame */
            f.id = (uint32_t)(data[1] | (data[2] << 8)) & 0x7FFu;
            memcpy(f.data, &data[3], 3u);
            break;
        }
        if (f.len > 8u) f.len = 8u;
        if (f.id != 0u) arm_co_boot_rx(&b, &f, now);
        now += 1000u;
        data += 6;
        size -= 6;
    }
    if (b.n_log > ARM_CO_BOOT_LOG_MAX) abort();
    if (rc == -1 && b.fault.code == ARM_CO_FAULT_NONE) abort();
    if (rc == 0 && (b.node[0].state != ARM_CO_NODE_ENABLED || b.node[1].state != ARM_CO_NODE_ENABLED)) abort();
    for (unsigned i = 0; rc == 0 && i < 2u; ++i) { /* an enabled drive's units were settled: never a 0 */
        arm_co_units_t u;
        if (arm_co_boot_units(&b, i, &u) != 0) abort();
    }
    return 0;
}
