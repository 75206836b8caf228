/* The CANopen master's faults as one line (arm_canopen_boot, arm_controller --protocol canopen). */
#ifndef ARM_CANOPEN_TEXT_H
#define ARM_CANOPEN_TEXT_H

#include <stddef.h>
#include <stdint.h>

#include "arm/co_boot.h"

/* "node 2: 0x6060:00: SDO abort 0x06090030 (value range of parameter exceeded)" and the like. */
void canopen_fault_text(const arm_co_fault_t *f, char *out, size_t cap);
/* 0x6502's modes by name: "pp, pv, hm, csp" ("none" for none). */
void canopen_modes_text(uint32_t modes, char *out, size_t cap);

/* A whole number in [lo, hi] (decimal or 0x hex, no sign); -1 otherwise. */
int canopen_parse_u32(const char *s, uint32_t lo, uint32_t hi, uint32_t *out);

/* --node "ID[,rated=N][,encoder=INC][,gear=M/S][,torque_unit=mNm|uNm][,efficiency=E][,limit=NM]
 * [,accept_no_master_watchdog=true][,vendor=X][,product=X]" into nc: the units the drive table gives
 * (the drive's objects must equal them; flagged in nc->expect; rated, the motor's, in the drive's
 * torque unit), the gear's efficiency, the joint's torque limit the drive must give, and whether a
 * drive without a master watchdog is accepted; -1 with one line naming the field (arm_canopen_boot,
 * arm_controller). */
int canopen_parse_node(const char *arg, arm_co_node_config_t *nc, char *err, size_t cap);

#endif
