/* The contract's default PDOs and their units, for the port and drive layer (the control core
 * keeps SI units: rad, rad/s, N m).
 *   RPDO1 (0x200 + id, 4 bytes): controlword u16, target torque 0x6071 i16 (per-mille of 0x6076)
 *   TPDO1 (0x180 + id, 8 bytes): position actual 0x6064 i32, velocity actual 0x606C i32 (increments,
 *                                increments/s of the motor encoder)
 *   TPDO2 (0x280 + id, 4 bytes): torque actual 0x6077 i16 (per-mille), statusword 0x6041 u16
 * Units, each drive's own as the boot read them (arm_co_boot_units), as CiA 402 defines them:
 * joint rad = increments / (0x608F.1 / 0x608F.2 increments per motor revolution * 0x6091.1 / 0x6091.2
 * motor per shaft revolutions) * 2 pi; joint N m = per-mille / 1000 * 0x6076 (the MOTOR's rated
 * torque, in mN m, CiA 402's unit, or another the drive table names: maxon's EPOS4 gives µN m)
 * * 0x6091.1 / 0x6091.2 (the gear multiplies the motor's torque at the driving shaft) * the gear's
 * efficiency (the drive table's, 1 unless it says otherwise). Torque out is rounded to the nearest
 * per-mille (halves away from zero) and saturated to +-max_permille (0x6072, <= 32767); a
 * non-finite torque is sent as 0. One quantum at the joint is 0x6076 * gear * efficiency / 1000
 * (0.150086 N m for 1486 mN m behind 101:1). */
#ifndef ARM_CO_PDO_H
#define ARM_CO_PDO_H

#include <stdint.h>

#include "arm/can_frame.h"

typedef struct {
    double joint_rated_torque_nm; /* 1000 per-mille at the joint: 0x6076 in N m * gear * efficiency */
    double increments_per_rad; /* 0x608F.1 * 0x6091.1 / 0x6091.2 / (2 pi) */
    int16_t max_permille;    /* saturation of the target torque, 1..32767 */
} arm_co_units_t;

/* rated_torque (the motor's, 0x6076) in units of which torque_units_per_nm make a N m (1000: mN m);
 * gear_efficiency in (0, 1]. -1 if a value is zero or the efficiency is out of range. */
int arm_co_units_init(arm_co_units_t *u, uint32_t rated_torque, uint32_t torque_units_per_nm,
                      double gear_efficiency, uint32_t encoder_increments, uint32_t encoder_revs,
                      uint32_t gear_motor_revs, uint32_t gear_shaft_revs, int16_t max_permille);
/* The largest torque the drive gives at the joint, N m: max_permille of the rated torque there. */
double arm_co_units_max_joint_torque_nm(const arm_co_units_t *u);

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
