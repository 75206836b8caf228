/* The contract's default PDOs and their units, for the port and drive layer (the control core
 * keeps SI units: rad, rad/s, N m).
 *   RPDO1 (0x200 + id, 4 bytes): controlword u16, target torque 0x6071 i16 (per-mille of 0x6076)
 *   TPDO1 (0x180 + id, 8 bytes): position actual 0x6064 i32, velocity actual 0x606C i32 (increments,
 *                                increments/s of the motor encoder)
 *   TPDO2 (0x280 + id, 4 bytes): torque actual 0x6077 i16 (per-mille), statusword 0x6041 u16
 * Units, each drive's own as the boot read them (arm_co_boot_units): joint rad = increments /
 * (0x608F.1 / 0x608F.2 increments per motor revolution * 0x6091.1 / 0x6091.2 motor per shaft
 * revolutions) * 2 pi; N m = per-mille / 1000 * 0x6076 rated torque (in mN m, CiA 402's unit, or another
 * the drive table names: maxon's EPOS4 gives µN m). Torque out is rounded to
 * the nearest per-mille (halves away from zero) and saturated to +-max_permille (0x6072, <= 32767);
 * a non-finite torque is sent as 0. One quantum is rated / 1000 (0.15 N m at 150 N m). */
#ifndef ARM_CO_PDO_H
#define ARM_CO_PDO_H

#include <stdint.h>

#include "arm/can_frame.h"

typedef struct {
    double rated_torque_nm;  /* 0x6076 / 1000 */
    double increments_per_rad; /* 0x608F.1 * 0x6091.1 / 0x6091.2 / (2 pi) */
    int16_t max_permille;    /* saturation of the target torque, 1..32767 */
} arm_co_units_t;

/* rated_torque in units of which torque_units_per_nm make a N m (1000: mN m). -1 if a value is zero. */
int arm_co_units_init(arm_co_units_t *u, uint32_t rated_torque, uint32_t torque_units_per_nm,
                      uint32_t encoder_increments, uint32_t encoder_revs, uint32_t gear_motor_revs,
                      uint32_t gear_shaft_revs, int16_t max_permille);

int16_t arm_co_torque_to_permille(const arm_co_units_t *u, float torque_nm);
float arm_co_permille_to_torque(const arm_co_units_t *u, int16_t permille);
float arm_co_increments_to_rad(const arm_co_units_t *u, int32_t increments);
int32_t arm_co_rad_to_increments(const arm_co_units_t *u, float rad); /* saturating, nearest */

void arm_co_pack_rpdo1(uint8_t node, uint16_t controlword, int16_t target_permille, arm_can_frame_t *out);
/* 0 and the values if f is node's TPDO1 (TPDO2) of the right length, else -1. */
int arm_co_unpack_tpdo1(uint8_t node, const arm_can_frame_t *f, int32_t *position_inc, int32_t *velocity_inc_s);
int arm_co_unpack_tpdo2(uint8_t node, const arm_can_frame_t *f, int16_t *torque_permille, uint16_t *statusword);

/* TPDO1 and TPDO2 in SI units. */
void arm_co_state_si(const arm_co_units_t *u, int32_t position_inc, int32_t velocity_inc_s,
                     int16_t torque_permille, float *q_rad, float *qd_rad_s, float *tau_nm);

#endif
