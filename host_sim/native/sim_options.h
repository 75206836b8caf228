/* arm_sim's command line. */
#ifndef ARM_SIM_OPTIONS_H
#define ARM_SIM_OPTIONS_H

#include "sim_arm.h"
#include "sim_canopen_loop.h"
#include "sim_loop.h"
#include "sim_plant.h"

typedef struct {
    char model[1024];
    char plant[1024];    /* the true arm when it differs from the nominal model ("": the same) */
    char keyframe[64];
    char lcm_url[512];
    char summary[1024];
    char capture[1024];  /* candump log of every frame ("": none) */
    int capture_wall;    /* its timestamps: the wall clock (realtime runs), else simulated time */
    char bus_args[ARM_CAN_BUS_SET_MAX][ARM_CAN_BUS_SPEC_MAX];
    unsigned n_bus_args;
    int n_viscous, n_coulomb; /* values given (must equal the arm's joints) */
    sim_uncertainty_t unc;
    sim_config_t cfg;
    long bench_mj_steps; /* > 0: time bare mj_step on the model and exit */
    int substeps;        /* MuJoCo steps per period */
    sim_protocol_t protocol; /* what the drives speak on the bus */
    sim_co_config_t co;      /* --protocol canopen: the drives' configuration */
    int co_given;            /* a canopen-only option was given */
    sim_plant_truth_t truth; /* --serve and the plant's truth (sim_plant.h) */
    char sessions[1024];     /* --sessions */
    double start_pose[SIM_MAX_JOINTS]; /* --start-pose: rad per joint */
    int n_start_pose;        /* values given (0: the keyframe; else the arm's joint count) */
    uint32_t brake_given;    /* bit j: --brake gave joint j + 1's */
} sim_options_t;

/* 0: run; 1: --help printed; -1: bad argument, message (naming the option) in err. */
int sim_options_parse(int argc, char **argv, sim_options_t *o, char *err, unsigned long errcap);
/* What depends on the model (joint count): the bus assignment, the friction lists, the brakes, the
 * start pose (set on the arm here: inside its joints' ranges). */
int sim_options_finish(sim_options_t *o, sim_arm_t *arm, char *err, unsigned long errcap);

#endif
