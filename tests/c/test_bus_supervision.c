/* The bus master's supervision of a period (arm_bus_supervise): what every port stops the arm for,
 * in order, each named with its drive, and each reported once. */
#include <string.h>

#include "arm/drive_bus.h"
#include "check.h"

#define ALL ((uint32_t)((1ull << ARM_N_JOINTS) - 1u))

static void all_states_in(arm_drive_bus_t *b, uint16_t statusword)
{
    b->fresh_mask = ALL;
    for (int j = 0; j < ARM_N_JOINTS; ++j) b->statusword[j] = statusword;
}

int main(void)
{
    arm_drive_bus_t b;
    arm_bus_init(&b);
    all_states_in(&b, 0x0237u); /* operation enabled */
    CHECK(arm_bus_supervise(&b, 1, 1).condition == ARM_BUS_WELL);

    b.fresh_mask = ALL & ~(1u << 1);
    arm_bus_fault_t f = arm_bus_supervise(&b, 1, 1);
    CHECK(f.condition == ARM_BUS_STATES_MISSING && f.joint == 1);
    CHECK(arm_bus_supervise(&b, 0, 1).condition == ARM_BUS_WELL); /* realtime: the watchdog's job */

    all_states_in(&b, 0x0237u);
    b.emcy_mask = 1u << 0;
    b.last_emcy_code[0] = 0x2310u;
    f = arm_bus_supervise(&b, 1, 1);
    CHECK(f.condition == ARM_BUS_DRIVE_EMCY && f.joint == 0 && f.value == 0x2310u);
    CHECK(arm_bus_supervise(&b, 1, 1).condition == ARM_BUS_WELL); /* reported once */

    b.duplicate_mask = 1u << (ARM_N_JOINTS - 1);
    f = arm_bus_supervise(&b, 1, 1);
    CHECK(f.condition == ARM_BUS_DUPLICATE_STATE && f.joint == ARM_N_JOINTS - 1);
    b.duplicate_mask = 0u;

    b.rx.foreign_master += 3u;
    f = arm_bus_supervise(&b, 1, 1);
    CHECK(f.condition == ARM_BUS_FOREIGN_MASTER && f.value == 3u && f.joint == -1);
    CHECK(arm_bus_supervise(&b, 1, 1).condition == ARM_BUS_WELL); /* counted from the last period */

    b.statusword[2] = 0x0218u; /* fault */
    f = arm_bus_supervise(&b, 1, 1);
    CHECK(f.condition == ARM_BUS_LEFT_ENABLED && f.joint == 2 && f.value == 0x0218u);
    CHECK(arm_bus_supervise(&b, 1, 0).condition == ARM_BUS_WELL); /* enabling: not expected yet */

    /* two at once: the first in order (a lost drive before what the others said) */
    b.fresh_mask = ALL & ~1u;
    b.emcy_mask = 1u << 1;
    CHECK(arm_bus_supervise(&b, 1, 1).condition == ARM_BUS_STATES_MISSING);
    CHECK(strcmp(arm_bus_condition_str(ARM_BUS_FOREIGN_MASTER), "another master on the bus") == 0);
    TEST_MAIN_END();
}
