/* The CANopen master's faults as one line (canopen_text.h). */
#include "canopen_text.h"

#include <stdio.h>

#include "arm/co_sdo.h"

void canopen_fault_text(const arm_co_fault_t *f, char *out, size_t cap)
{
    switch (f->code) {
    case ARM_CO_FAULT_SDO_ABORT:
    case ARM_CO_FAULT_CLIENT_ABORT:
        snprintf(out, cap, "node %u: 0x%04X:%02X: %s 0x%08X (%s)", f->node, f->index, f->sub,
                 f->code == ARM_CO_FAULT_SDO_ABORT ? "SDO abort" : "master aborted the response with",
                 f->abort_code, arm_co_abort_text(f->abort_code));
        break;
    case ARM_CO_FAULT_NO_ANSWER:
        snprintf(out, cap, "node %u: 0x%04X:%02X: no answer after %u tries (SDO abort 0x%08X sent)", f->node,
                 f->index, f->sub, f->tries, f->abort_code);
        break;
    case ARM_CO_FAULT_WRONG_VALUE:
        snprintf(out, cap, "node %u: 0x%04X:%02X: read 0x%08X, expected 0x%08X", f->node, f->index, f->sub,
                 f->value, f->expected);
        break;
    case ARM_CO_FAULT_STATE_TIMEOUT:
        snprintf(out, cap, "node %u: 0x6041:00: statusword 0x%04X did not reach 0x%02X (under mask 0x%02X)", f->node,
                 f->value, f->expected & 0xFFu, f->expected >> 8);
        break;
    case ARM_CO_FAULT_DRIVE_FAULT:
        snprintf(out, cap, "node %u: 0x6041:00: statusword 0x%04X shows fault (bit 3) while waiting for 0x%02X",
                 f->node, f->value, f->expected & 0xFFu);
        break;
    case ARM_CO_FAULT_BAD_CONFIG:
        snprintf(out, cap, "node %u: bad configuration (value %u)", f->node, f->value);
        break;
    case ARM_CO_FAULT_NONE:
    default:
        snprintf(out, cap, "no fault");
        break;
    }
}
