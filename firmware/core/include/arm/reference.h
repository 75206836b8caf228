/* Smooth joint reference: starts at rest where the arm is, bounded velocity and acceleration. */
#ifndef ARM_REFERENCE_H
#define ARM_REFERENCE_H

#include "arm/robot_model.h"

typedef struct {
    float hold_s;              /* q_d = q0 for this long before the motion starts */
    float q0[ARM_N_JOINTS];    /* start pose (the measured pose when the run begins) */
    float amp[ARM_N_JOINTS];   /* rad */
    float omega[ARM_N_JOINTS]; /* rad/s */
} arm_reference_t;

/* q_d = q0 while t < hold_s, then q0 + amp (1 - cos(omega (t - hold_s))): the arm settles on its
 * start pose first (drives enabled, gravity taken, estimator converged), and the motion starts
 * at rest with no step; |qd_d| <= amp omega, |qdd_d| <= amp omega^2. */
void arm_reference_default(arm_reference_t *ref, const float q0[ARM_N_JOINTS]);
/* With a duration that is a whole number of every joint's periods the reference also ends at
 * rest (qd_d = 0) where it started. */
void arm_reference_set(arm_reference_t *ref, const float q0[ARM_N_JOINTS],
                       const float amp[ARM_N_JOINTS], const float freq_hz[ARM_N_JOINTS]);
void arm_reference_set_hold(arm_reference_t *ref, float hold_s);
void arm_reference_eval(const arm_reference_t *ref, float t, float q_d[ARM_N_JOINTS],
                        float qd_d[ARM_N_JOINTS], float qdd_d[ARM_N_JOINTS]);

#endif
