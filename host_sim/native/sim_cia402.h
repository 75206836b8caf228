/* The CiA 402 drive profile as the emulated CANopen drive applies it: which modes it takes (0x6502
 * supported drive modes; it moves only in cyclic synchronous torque), and the profile's units from
 * the dictionary's scaling objects (0x608F encoder resolution, 0x6091 gear ratio, 0x6076 the
 * motor's rated torque), or, for a drive whose file lacks one, from the drive table's value of it
 * (the drive's own setting that no object shows). The drive's torque is its motor's: the joint
 * feels it times the gear and the gear's efficiency. The power state machine is sim_drive.c's
 * sim_cia402_next. */
#ifndef ARM_SIM_CIA402_H
#define ARM_SIM_CIA402_H

#include <stdint.h>

#include "sim_canopen_od.h"

#define SIM_CIA402_MODE_NONE 0
#define SIM_CIA402_MODE_CST 10 /* cyclic synchronous torque: the only mode this drive moves in */

/* What the simulator commissions a drive with (the drive table, arm_sim --node; 0: the file's). */
typedef struct {
    uint32_t rated_torque_mnm;   /* 0x6076, the motor's */
    uint32_t encoder_increments; /* 0x608F.1 */
    uint32_t gear_motor, gear_shaft; /* 0x6091.1, .2 */
    uint32_t torque_units_per_nm;    /* 0x6076's unit: 1000 mN m (CiA 402's; 0 means it), 1000000 µN m */
    double gear_efficiency;          /* the gear's, (0, 1]; 0 means 1 (no object holds it) */
    uint32_t quick_stop_decel;       /* 0x6085 */
    uint32_t max_torque_permille;    /* 0x6072: a motor sized below the joint's limit gives it above 1000 */
} sim_co_preset_t;

typedef struct {
    double inc_per_rad;    /* position encoder increments per joint radian */
    double joint_rated_nm; /* 1000 per-mille at the joint: 0x6076 in N m (through its unit) x gear x efficiency */
} sim_cia402_scale_t;

/* Mode 0 always; 1..16 if 0x6502 has bit mode - 1 (CiA 402: bit 9 is CST), or, without 0x6502,
 * CST alone; no manufacturer-specific (negative) mode. */
int sim_cia402_mode_supported(const sim_co_od_t *od, int64_t mode);
/* -1 if the drive has no value for one of the three (neither an object nor the preset) or it is 0. */
int sim_cia402_scale(const sim_co_od_t *od, const sim_co_preset_t *own, sim_cia402_scale_t *sc);
/* Joint quantities in the profile's units, rounded to nearest and saturated to the type: a joint
 * torque as per-mille of the motor's rated torque (through the gear). */
int32_t sim_cia402_increments(const sim_cia402_scale_t *sc, double rad);
int16_t sim_cia402_permille(const sim_cia402_scale_t *sc, double nm);
/* The joint torque a target torque (per-mille of the motor's rated torque) gives, within the max
 * torque (0x6072, per-mille) and the joint's own limit (N m). */
double sim_cia402_target_nm(const sim_cia402_scale_t *sc, int32_t target_permille, uint32_t max_permille,
                            double limit_nm);

#endif
