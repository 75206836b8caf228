/* One CANopen node's object dictionary: the EDS's table (firmware/protocol/cia402_servo.eds,
 * turned into SIM_CO_OD by gen/eds.py at build time) and this node's values. Reads and writes
 * check what the table says (existence, access, length, limits); what depends on the drive's
 * state (PDO mappings, the mode of operation) is the node's to check (sim_canopen_node.c). */
#ifndef ARM_SIM_CANOPEN_OD_H
#define ARM_SIM_CANOPEN_OD_H

#include <stdint.h>

#include "sim_co_od_table.h"

/* CiA 301 SDO abort codes. */
#define SIM_CO_ABORT_TOGGLE 0x05030000u
#define SIM_CO_ABORT_TIMEOUT 0x05040000u
#define SIM_CO_ABORT_COMMAND 0x05040001u
#define SIM_CO_ABORT_UNSUPPORTED_ACCESS 0x06010000u
#define SIM_CO_ABORT_WRITE_ONLY 0x06010001u
#define SIM_CO_ABORT_READ_ONLY 0x06010002u
#define SIM_CO_ABORT_NO_OBJECT 0x06020000u
#define SIM_CO_ABORT_NOT_MAPPABLE 0x06040041u
#define SIM_CO_ABORT_PDO_LENGTH 0x06040042u
#define SIM_CO_ABORT_LENGTH 0x06070010u
#define SIM_CO_ABORT_NO_SUB 0x06090011u
#define SIM_CO_ABORT_RANGE 0x06090030u
#define SIM_CO_ABORT_STATE 0x08000022u

#define SIM_CO_VALUE_MAX 64u /* the longest value an SDO moves (the device name) */

typedef struct {
    uint8_t node_id;
    uint32_t value[SIM_CO_OD_N]; /* raw bits, little-endian order of the type's size */
} sim_co_od_t;

/* Every value to its EDS default (comm_only: the communication area 0x1000..0x1FFF only, as NMT
 * reset communication does). */
void sim_co_od_reset(sim_co_od_t *od, uint8_t node_id, int comm_only);
/* The table row of (index, sub), or -1 with the abort code (no object / no sub-index). */
int sim_co_od_find(uint16_t index, uint8_t sub, uint32_t *abort_code);
/* A value the drive itself reads or sets (no access check); an entry the EDS lacks reads 0. */
uint32_t sim_co_od_get(const sim_co_od_t *od, uint16_t index, uint8_t sub);
int32_t sim_co_od_get_signed(const sim_co_od_t *od, uint16_t index, uint8_t sub);
void sim_co_od_set(sim_co_od_t *od, uint16_t index, uint8_t sub, uint32_t raw);
/* SDO upload: the value's bytes; 0 or the abort code. */
uint32_t sim_co_od_read(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap,
                        unsigned *len);
/* SDO download, checked against the table only: 0 and the raw value, or the abort code. */
uint32_t sim_co_od_check_write(uint16_t index, uint8_t sub, const uint8_t *data, unsigned len, uint32_t *raw);

#endif
