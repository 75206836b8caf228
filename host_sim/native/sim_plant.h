/* The plant (arm_sim --serve, armctl plant): the simulated arm as the "arm" on the bus, for
 * controllers that come and go, and the truth about it that a controller never sees.
 *
 * Sessions: a master boots the drives, runs its SYNCs and stops them (NMT stop) or falls silent;
 * the plant then keeps the arm's physics going on the wall clock, its drives disabled and their
 * holding brakes (the drive table's: sim_power_stage.h) closed, until the next master speaks, and says how far each joint moved in the
 * SETTLE_S after each stop. Inside a session the arm moves on the master's SYNC only, as in every
 * HIL run: a rehearsal is the same whatever the machine's latency.
 *
 * The truth (--rotor-inertia, --joint-stiffness-scale, --encoder-offset, --gear-factor,
 * --reversed-motor, --reversed-encoder; the start pose is --start-pose, friction and payload the
 * uncertainty's --viscous, --coulomb, --payload-kg): what the model the controller was built
 * from does not say, or says wrong, and a commissioning must find. */
#ifndef ARM_SIM_PLANT_H
#define ARM_SIM_PLANT_H

#include <stdint.h>

#include "sim_arm.h"

#define SIM_PLANT_SESSIONS_MAX 64 /* the summary keeps the last ones */
#define SIM_PLANT_SETTLE_S 2.0     /* the motion after a stop is measured over this */

typedef struct {
    int serve;                              /* --serve */
    double rotor_inertia[SIM_MAX_JOINTS];   /* kg m^2 added to each joint's armature */
    int n_rotor_inertia;
    double stiffness_scale[SIM_MAX_JOINTS]; /* each joint's gear stiffness times this (flexible plant) */
    int n_stiffness_scale;
    double encoder_offset[SIM_MAX_JOINTS];  /* rad added to the position each drive reports */
    int n_encoder_offset;
    double gear_factor[SIM_MAX_JOINTS];     /* the real gear over the drive's 0x6091: positions and torques scale */
    int n_gear_factor;
    uint32_t reversed_motor;                /* bit j: joint j's motor turns the other way */
    uint32_t reversed_encoder;              /* bit j: joint j's encoder counts the other way */
} sim_plant_truth_t;

typedef struct {
    int index;              /* 1, 2, ... */
    uint64_t periods;       /* SYNC periods the master ran */
    char ended[24];         /* "stopped" (NMT stop) or "master silent" */
    double moved_after_stop_rad[SIM_MAX_JOINTS]; /* the largest |q - q at the stop| in the window */
    double window_s;        /* how long it was watched (SETTLE_S, or less when the next master came) */
    int complete;           /* the window is over */
} sim_plant_session_t;

typedef struct {
    const sim_plant_truth_t *truth;
    sim_arm_t *arm;
    int in_session;
    uint64_t session_start_period;
    double stop_q[SIM_MAX_JOINTS];
    double stop_t;          /* simulated time of the last stop */
    int watching;           /* the window after a stop is running */
    sim_plant_session_t sessions[SIM_PLANT_SESSIONS_MAX];
    int n_sessions;         /* sessions ever (the array keeps the last SESSIONS_MAX) */
    uint64_t idle_steps;    /* periods simulated on the wall clock between sessions */
    uint64_t idle_slips;    /* times the wall clock ran ahead of the physics (a slow machine): time dropped */
} sim_plant_t;

void sim_plant_truth_default(sim_plant_truth_t *t);
/* The truth into the arm (rotor inertia, stiffness): 0, or -1 with the option named in err. */
int sim_plant_apply(sim_plant_t *p, const sim_plant_truth_t *truth, sim_arm_t *arm, char *err, unsigned long errcap);
/* What joint j's drive reads (its encoder): the true q, qd as the truth turns them. */
void sim_plant_sense(const sim_plant_t *p, int j, double *q, double *qd);
/* The torque joint j gets when its drive applies tau. */
double sim_plant_actuate(const sim_plant_t *p, int j, double tau);
/* A master's SYNC began a session. */
void sim_plant_session_begin(sim_plant_t *p, uint64_t period);
/* Its end ("stopped", "master silent"): the window after the stop begins. */
void sim_plant_session_end(sim_plant_t *p, uint64_t period, const char *how);
/* After each step: the window's bookkeeping; 1 when a session's record just became final. */
int sim_plant_after_step(sim_plant_t *p);
/* The last session's record (NULL: none yet). */
const sim_plant_session_t *sim_plant_last(const sim_plant_t *p);
/* Every session kept, as JSON, atomically (--sessions): 0, or -1 with a message in err. */
int sim_plant_write(const sim_plant_t *p, const char *path, char *err, unsigned long errcap);
/* The line the plant prints when a session's record is final. */
void sim_plant_describe(const sim_plant_t *p, const sim_plant_session_t *s, char *out, unsigned long cap);

#endif
