/* The CiA 402 drive profile as the emulated CANopen drive applies it: which modes it runs, and the
 * profile's units from the object dictionary's scaling objects (0x608F encoder resolution, 0x6091
 * gear ratio, 0x6076 rated torque). The power state machine is sim_drive.c's sim_cia402_next. */
#ifndef ARM_SIM_CIA402_H
#define ARM_SIM_CIA402_H

#include <stdint.h>

#include "sim_canopen_od.h"

#define SIM_CIA402_MODE_NONE 0
#define SIM_CIA402_MODE_CST 10 /* cyclic synchronous torque: the only mode this drive runs */

typedef struct {
    double inc_per_rad; /* position encoder increments per joint radian */
    double rated_nm;    /* 0x6076 in N m */
} sim_cia402_scale_t;

int sim_cia402_mode_supported(int32_t mode);
void sim_cia402_scale(const sim_co_od_t *od, sim_cia402_scale_t *sc);
/* Joint quantities in the profile's units, rounded to nearest and saturated to the type. */
int32_t sim_cia402_increments(const sim_cia402_scale_t *sc, double rad);
int16_t sim_cia402_permille(const sim_cia402_scale_t *sc, double nm);
/* The torque a target torque (per-mille of rated) asks for, within the max torque (0x6072,
 * per-mille) and the joint's own limit (N m). */
double sim_cia402_target_nm(const sim_cia402_scale_t *sc, int32_t target_permille, uint32_t max_permille,
                            double limit_nm);

#endif
