/* Smooth joint reference: starts at rest where the arm is, bounded velocity and acceleration. */
#ifndef ARM_REFERENCE_H
#define ARM_REFERENCE_H

#include "arm/robot_model.h"

typedef struct {
    float q0[ARM_N_JOINTS];    /* start pose (the measured pose when the run begins) */
    float amp[ARM_N_JOINTS];   /* rad */
    float omega[ARM_N_JOINTS]; /* rad/s */
} arm_reference_t;

/* q_d = q0 + amp (1 - cos(omega t)): q_d(0) = q0 and qd_d(0) = 0, so no start-up step;
 * |qd_d| <= amp omega, |qdd_d| <= amp omega^2. */
void arm_reference_default(arm_reference_t *ref, const float q0[ARM_N_JOINTS]);
void arm_reference_eval(const arm_reference_t *ref, float t, float q_d[ARM_N_JOINTS],
                        float qd_d[ARM_N_JOINTS], float qdd_d[ARM_N_JOINTS]);

#endif
