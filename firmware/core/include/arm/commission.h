/* Commissioning: checks each joint before the arm is trusted with a task (armctl commission).
 *
 * The arm is held where it stands (the controller's hold: inverse dynamics with gravity and a PD
 * around the start pose q0), and each joint in turn is tested while the others stay held:
 *
 *   settle  hold q0; the mean commanded torque of the settle's last window is the holding torque
 *   pulse+  joint j open loop: the holding torque plus delta (a few % of its limit, above its
 *           friction) until it moved trip_rad or pulse_max_s passed; its acceleration is fitted
 *           (least squares, q = q_start + v0 t + a t^2 / 2). A joint that moves the wrong way is
 *           reversed (motor or encoder): the sequence stops before the loop is closed on it
 *   settle
 *   sweep   closed loop, joint j from q0 to -A, +A, -A and back at constant speed: the commanded
 *           torque where it crosses q0 going up and going down. Their mean is the gravity torque
 *           (friction and damping change sign with the motion and cancel), half their difference
 *           the friction and damping
 *   settle, pulse-, settle (the same pulse the other way)
 *
 * No joint may leave q0 by more than bound_rad at any time (2 deg): the sequence stops, naming it.
 * The numbers are the port's to report and the host's to judge against the model (direction,
 * inertia, gravity: tools/commission); this module only runs the sequence, allocation-free.
 * It is a reference source for arm_ctl_step: each period it gives q_d, qd_d, qdd_d and the joint
 * whose torque is set open loop (arm_ctl_input_t's torque_override). */
#ifndef ARM_COMMISSION_H
#define ARM_COMMISSION_H

#include <stdint.h>

#include "arm/controller.h"
#include "arm/reference.h"

typedef enum {
    ARM_CM_RUNNING = 0,
    ARM_CM_DONE,        /* every joint tested; the arm is held at q0 */
    ARM_CM_LEFT_BOUND,  /* a joint left q0 by more than bound_rad (why_joint; why_value: how far, rad) */
    ARM_CM_REVERSED,    /* the tested joint moved against its pulse (why_value: how far, rad) */
    ARM_CM_STUCK,       /* the tested joint did not move trip_rad within pulse_max_s (why_value: how far) */
} arm_cm_status_t;

typedef enum { ARM_CM_SETTLE = 0, ARM_CM_PULSE, ARM_CM_SWEEP } arm_cm_phase_t;

typedef struct {
    float bound_rad;        /* no joint leaves q0 by more */
    float trip_rad;         /* a pulse ends once its joint moved this far */
    float pulse_max_s;      /* ... or after this long */
    float settle_s;         /* each hold between the tests */
    float first_settle_s;   /* the first hold, after the drives were enabled */
    float hold_window_s;    /* the holding torque: the mean over the settle's last this long */
    float sweep_rad;        /* A */
    float sweep_speed;      /* rad/s */
    float sweep_accel;      /* rad/s^2 at the turns */
    float sweep_window_rad; /* the torque is averaged while |q - q0| is below this, at constant speed */
    float pulse_nm[ARM_N_JOINTS];
    uint32_t joints;        /* bit j: test joint j */
} arm_cm_config_t;

typedef struct {
    float delta;       /* N m above (below) the holding torque */
    float tau_hold;    /* the holding torque before it, N m */
    float q_start;     /* rad */
    float duration_s;
    float accel;       /* rad/s^2, fitted */
    float moved;       /* rad, at its end */
    uint32_t samples;
} arm_cm_pulse_t;

typedef struct {
    float speed;              /* rad/s */
    float tau_up, tau_down;   /* mean commanded torque across q0, moving up / down */
    float q_up, q_down;       /* mean position over those samples */
    uint32_t n_up, n_down;
} arm_cm_sweep_t;

typedef struct {
    int tested;         /* its sequence ran to the end */
    float q0;
    arm_cm_pulse_t pulse[2]; /* + then - */
    arm_cm_sweep_t sweep;
    float excursion;    /* the largest |q - q0| seen, rad */
} arm_cm_joint_t;

typedef struct {
    arm_cm_config_t cfg;
    float period_s;
    float q0[ARM_N_JOINTS];
    arm_cm_status_t status;
    int joint;          /* the joint under test (-1 before the first, or when done) */
    int step;           /* 0..6: settle, pulse+, settle, sweep, settle, pulse-, settle */
    float t;            /* s into the step */
    uint32_t k;         /* periods into the step */
    int began;          /* a step (or sweep leg) began this period: its clock starts next period */
    /* the step's running sums: holding torque; a pulse's fit in periods (n, sum k^i, sum dq k^i) */
    float hold_sum;
    uint32_t hold_n;
    double fit_s[5];
    double fit_q[3];
    float pulse_tau;    /* the open-loop torque of the running pulse */
    arm_move_t sweep_leg;
    int sweep_leg_index; /* 0..3: to -A, to +A, to -A, to q0 */
    arm_cm_joint_t j[ARM_N_JOINTS];
    int why_joint;
    float why_value;
} arm_commission_t;

/* The defaults: a 2 deg bound, pulses that end at 0.75 deg or 0.4 s, 0.4 s holds (1 s first), a
 * 1.5 deg sweep at 5 deg/s, every joint; pulse_nm is the caller's (per joint: above its friction). */
void arm_commission_default_config(arm_cm_config_t *cfg);
/* 0, or -1 for a configuration that cannot run (a bound below the trip or the sweep, a pulse of 0). */
int arm_commission_init(arm_commission_t *c, const arm_cm_config_t *cfg, float period_s,
                        const float q0[ARM_N_JOINTS]);
/* One period: from this period's measured state and the torque commanded last period, fills in's
 * q_d, qd_d, qdd_d and torque override; returns the sequence's status (RUNNING until it ends; after
 * it ends in, the arm is held at q0). */
arm_cm_status_t arm_commission_step(arm_commission_t *c, const float q[ARM_N_JOINTS], const float tau_last[ARM_N_JOINTS],
                                    arm_ctl_input_t *in);
const char *arm_cm_status_str(arm_cm_status_t s);
/* What the running step is, for a message ("settle", "pulse+", "sweep", ...). */
const char *arm_cm_step_str(const arm_commission_t *c);

#endif
