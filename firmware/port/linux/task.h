/* What the arm does once its drives are enabled (arm_controller --task): the reference source of the
 * control loop. Every task starts wherever the arm is: where its first point is not the measured
 * pose, a bounded move (arm_move_t: --move-speed, --move-accel) takes the arm there first.
 *
 *   reference   the reference (--ref-*) for --duration: around the pose the run starts at (a HIL
 *               run), or around the arm's home after the move there (--reference-origin home)
 *   hold        the measured pose, with gravity compensation, for --duration
 *   jog         one joint by a bounded angle at --jog-speed, the others held; then --end-hold
 *   trajectory  --trajectory's knots (the move to its first knot first); then --end-hold
 *   stream      a planner's reference over LCM (plan_stream.h): the first plan is moved to, later
 *               ones must continue from where the reference is; a stale stream stops the
 *               reference within STREAM_STOP_S and holds; a plan that jumps is refused (held)
 *   commission  arm/commission.h's sequence; then --end-hold
 *
 * A task that ends (all but hold and stream, which run for --duration) says so; the loop then
 * stops the arm the controlled way. */
#ifndef ARM_TASK_H
#define ARM_TASK_H

#include <stdint.h>

#include "arm/commission.h"
#include "arm/controller.h"
#include "arm/reference.h"
#include "options.h"
#include "telemetry.h"
#if !ARM_PORT_MCU
#include "plan_stream.h"
#endif

typedef enum { TASK_REFERENCE = 0, TASK_HOLD, TASK_JOG, TASK_TRAJECTORY, TASK_STREAM, TASK_COMMISSION } task_kind_t;

/* What a run's summary says of its task (summary.c). */
typedef struct {
    int begun;
    float start_move_s;               /* the move from the measured pose to the first point (0: none) */
    float start_move_rad;             /* its longest joint motion */
    float start_pose[ARM_N_JOINTS];   /* rad: the measured pose the task began at */
    float first_point[ARM_N_JOINTS];  /* rad */
    float task_s;                     /* the task's own length after the move (0: open-ended) */
    int ended;                        /* the task ran to its end */
    /* stream */
    uint64_t plans_taken, plans_refused, stale_events;
    int64_t last_seq;
    char last_refusal[160];
    /* how closely the arm followed while the controller ran the task: |q_d - q| per joint */
    float track_max[ARM_N_JOINTS];    /* rad */
    double track_sumsq[ARM_N_JOINTS]; /* rad^2 */
    uint32_t track_n;                 /* periods */
    /* commission: how it ended, and each joint's measurements (task_end copies them) */
    arm_cm_status_t cm_status;
    int cm_why_joint;
    float cm_why_value;
    char cm_step[16];
    int cm_joint_under_test;
    arm_cm_config_t cm_config;
    arm_cm_joint_t cm_joint[ARM_N_JOINTS];
    /* the controller's own model at what commissioning measured (its RNEA): each joint's gravity
     * torque where its sweep crossed its start pose and that torque's slope in its angle, and its
     * inertia (M_jj) at the start pose: what the measurements are judged against */
    float cm_gravity_model[ARM_N_JOINTS], cm_gravity_slope[ARM_N_JOINTS], cm_inertia_model[ARM_N_JOINTS];
} task_report_t;

typedef struct {
    const options_t *opt;
    telemetry_t *telem;
    task_report_t *report;
    int moving;          /* the bounded move (start move, jog) is running */
    float t_move_end;    /* s: when it ends (run time) */
    arm_move_t move;
    arm_reference_t ref;
    arm_traj_t traj;
    arm_commission_t cm;
    float hold[ARM_N_JOINTS]; /* the pose held (the end of a move, a stopped stream, the start) */
    float t_end;         /* s: the task is over after this (run time); < 0: open-ended */
    float t_released;    /* s: the drives' brakes are open (run time): the start pose held until then */
    float last_q_d[ARM_N_JOINTS], last_qd_d[ARM_N_JOINTS];
#if !ARM_PORT_MCU
    plan_stream_t stream;
    plan_point_t plan;   /* the plan being followed */
    int following;       /* a fresh plan is followed */
    int have_plan;       /* a plan was ever taken */
    float t_plan;        /* s: when it came */
    float t_stale;       /* s: when the stream went stale (the stop ramp's start) */
    float stop_q[ARM_N_JOINTS], stop_v[ARM_N_JOINTS];
    int stopping;
#endif
} task_t;

/* Parse-time: the options of a task go together (--jog with --task jog, ...) and the run's length
 * is the task's: one line in err, -1. given_*: whether the option was on the command line. */
int task_check_options(options_t *opt, int given_jog, int given_trajectory, char *err, unsigned long errcap);
/* Once every drive is operation enabled: the task from the measured pose q. -1 with the reason in
 * err (a stream that cannot be opened): the loop stops the arm. */
int task_begin(task_t *t, const options_t *opt, const float q[ARM_N_JOINTS], telemetry_t *telem, task_report_t *report,
               uint32_t k_run, char *err, unsigned long errcap);
/* One period at run time time_s (period k_run): in's reference (and a torque override) from the
 * measured q and last period's commanded torque. 1 once the task is over (the loop stops the arm),
 * -1 when it stopped the arm itself (commissioning's bound: the reason in err), else 0. */
int task_step(task_t *t, float time_s, uint32_t k_run, const float q[ARM_N_JOINTS], const float tau_last[ARM_N_JOINTS],
              arm_ctl_input_t *in, char *err, unsigned long errcap);
/* After each period's step: while the controller runs the task, how closely the arm follows. */
void task_track(task_t *t, const float e[ARM_N_JOINTS]);
void task_end(task_t *t);
const char *task_name(int kind);

#endif
