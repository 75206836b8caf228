/* Smooth joint reference: starts at rest where the arm is, bounded velocity and acceleration. */
#ifndef ARM_REFERENCE_H
#define ARM_REFERENCE_H

#include <stdint.h>

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

/* A bounded move between two poses: every joint on one normalised trapezoidal profile, so all
 * start and arrive together, at rest, and no joint exceeds v_max (rad/s) or a_max (rad/s^2). The
 * way a task begins wherever the arm is: from the measured pose to the task's first point. */
typedef struct {
    float q0[ARM_N_JOINTS]; /* from */
    float dq[ARM_N_JOINTS]; /* to - from */
    float t_acc;            /* s: accelerating (and, at the end, braking) */
    float t_total;          /* s: 0 when from and to are the same pose */
    float s_acc;            /* the profile's acceleration, 1/s^2 (s runs 0 -> 1) */
} arm_move_t;

/* 0, or -1 when v_max or a_max is not a positive finite number (the move is then the pose q0). */
int arm_move_plan(arm_move_t *m, const float from[ARM_N_JOINTS], const float to[ARM_N_JOINTS], float v_max,
                  float a_max);
/* t < 0: from; t >= t_total: to, at rest. */
void arm_move_eval(const arm_move_t *m, float t, float q_d[ARM_N_JOINTS], float qd_d[ARM_N_JOINTS],
                   float qdd_d[ARM_N_JOINTS]);

/* A trajectory through knots, each a time, a pose and a velocity: cubic Hermite segments, so q_d,
 * qd_d and qdd_d are exact at any time (qdd_d piecewise linear); a C2 spline's knot velocities give
 * a C2 trajectory. The knots are the caller's (static storage: the core allocates nothing); the
 * segment cursor only moves forward, so a period costs O(1) whatever the trajectory's length. */
typedef struct {
    const float *t;  /* n times, s, strictly increasing, t[0] = 0 */
    const float *q;  /* n x ARM_N_JOINTS, rad, row by row */
    const float *qd; /* n x ARM_N_JOINTS, rad/s */
    uint32_t n;      /* at least 2 */
    uint32_t seg;    /* the segment of the last evaluation */
} arm_traj_t;

/* 0, or -1 when the knots are fewer than 2, do not start at 0 or are not strictly increasing. */
int arm_traj_init(arm_traj_t *tr, const float *t, const float *q, const float *qd, uint32_t n);
float arm_traj_duration(const arm_traj_t *tr);
/* Before 0: the first knot; after the last: its pose, at rest. Times must not decrease from one
 * call to the next (the cursor); an earlier time restarts the search from the first segment. */
void arm_traj_eval(arm_traj_t *tr, float t, float q_d[ARM_N_JOINTS], float qd_d[ARM_N_JOINTS],
                   float qdd_d[ARM_N_JOINTS]);

#endif
