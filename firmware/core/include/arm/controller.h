/* The control step every port calls: inverse dynamics + method + safety layer. */
#ifndef ARM_CONTROLLER_H
#define ARM_CONTROLLER_H

#include <stdint.h>

#include "arm/baselines.h"
#include "arm/pm.h"
#include "arm/robot_model.h"
#include "arm_params.h"

/* Every method runs on the same inverse dynamics control and produces u_o and w_hat. */
typedef enum {
    ARM_METHOD_PD = 0,   /* u_o = -kp e - kd e_dot, w_hat = 0 */
    ARM_METHOD_PM,       /* the paper's method, decoupled estimator structure (the product) */
    ARM_METHOD_PM_PAPER, /* the paper's method as printed: K fed y directly */
    ARM_METHOD_GH2,      /* generalized-H2 controller alone (the paper's Example 1) */
    ARM_METHOD_TDE,      /* PD + time-delay estimation */
    ARM_METHOD_USDE_SMC, /* USDE estimator + sliding-mode control with a boundary layer */
    ARM_METHOD_COUNT
} arm_method_t;

typedef enum {
    /* The numbers and names are the registry's (controller-states, firmware/params/params.toml):
     * telemetry carries the number, tools/run/run_analysis.py reads the names from there too. */
    ARM_STATE_INIT = ARM_P_CONTROLLER_STATES_INIT,           /* configured, no valid input yet */
    ARM_STATE_RUNNING = ARM_P_CONTROLLER_STATES_RUNNING,     /* method output reaches the drives */
    ARM_STATE_FAULT = ARM_P_CONTROLLER_STATES_FAULT,         /* a fault was detected this period; the safe-stop output is commanded */
    ARM_STATE_SAFE_STOP = ARM_P_CONTROLLER_STATES_SAFE_STOP, /* latched after a fault or a stop: the arm held (gravity + damping) until re-initialised */
} arm_state_t;

typedef enum {
    ARM_FAULT_NONE = 0,
    ARM_FAULT_NONFINITE_INPUT,  /* NaN/Inf in q, qd or the reference */
    ARM_FAULT_NONFINITE_OUTPUT, /* the method produced NaN/Inf */
    ARM_FAULT_STALE_INPUT,      /* joint state older than watchdog_periods */
    ARM_FAULT_EXTERNAL,         /* the port reported a fault (bus, drive, peer lost) */
    /* Plausibility of the joint states, and of the drives' work (fault_joint names the joint): */
    ARM_FAULT_POSITION_RANGE,   /* a position outside the joint's range plus the margin */
    ARM_FAULT_VELOCITY_LIMIT,   /* a velocity above the joint's limit */
    ARM_FAULT_POSITION_STEP,    /* a position step the reported velocities cannot explain */
    ARM_FAULT_FOLLOWING_ERROR,  /* the tracking error above its limit */
    ARM_FAULT_TORQUE_MISMATCH,  /* the drive reports another torque than commanded, period after period */
} arm_fault_t;

/* The plausibility checks (arm_ctl_config_t.checks), each on by default. */
#define ARM_CHECK_POSITION_RANGE 0x01u
#define ARM_CHECK_VELOCITY 0x02u
#define ARM_CHECK_POSITION_STEP 0x04u
#define ARM_CHECK_FOLLOWING_ERROR 0x08u
#define ARM_CHECK_TORQUE 0x10u
#define ARM_CHECK_ALL 0x1Fu

#define ARM_TORQUE_REPORT_LAG_MAX 4u /* the commands kept for the torque check (torque_report_lag_max); a power of two */


typedef struct {
    arm_method_t method;
    arm_numeric_t numeric; /* pm, pm-paper, gh2: float32 or int32 fixed-point blocks */
    const arm_pm_design_t *design; /* pm, pm-paper, gh2: K and C (default &arm_pm_builtin_design) */
    float period_s;
    float kp; /* 1/s^2, pd and tde */
    float kd; /* 1/s, pd and tde */
    float tde_cutoff_hz;
    float usde_k; /* s, USDE filter time constant */
    float smc_lambda, smc_eta, smc_phi, smc_ks;
    float torque_limit[ARM_N_JOINTS];      /* Nm */
    float torque_rate_limit[ARM_N_JOINTS]; /* Nm per period */
    uint32_t watchdog_periods;             /* stale periods tolerated before safe stop */
    /* Plausibility: a violation is a named fault (safe stop). Defaults from the model. */
    uint32_t checks;                        /* ARM_CHECK_* bits */
    float q_min[ARM_N_JOINTS];              /* rad: the joint's range widened by a margin */
    float q_max[ARM_N_JOINTS];
    float velocity_limit[ARM_N_JOINTS];     /* rad/s */
    float step_tolerance;                   /* rad: |q - q_prev - (qd + qd_prev) T / 2| allowed */
    float following_error_limit[ARM_N_JOINTS]; /* rad */
    float torque_mismatch_limit[ARM_N_JOINTS]; /* Nm between reported and commanded torque */
    uint32_t torque_mismatch_periods;       /* consecutive periods of mismatch that make a fault */
    /* Periods from a command to the drive's report of the torque it applied: a report matches if
     * it is near any command of that window. 1..1 on the arm protocol (the state at SYNC k reports
     * the command of period k - 1); the CANopen port widens it (a synchronous RPDO acts one SYNC
     * later, a TPDO2 of every n-th SYNC reports up to n - 1 periods late). */
    uint32_t torque_report_lag_min;
    uint32_t torque_report_lag_max;         /* at most ARM_TORQUE_REPORT_LAG_MAX */
    /* The safe stop's hold: gravity compensation plus damping, the model's torque at the joints'
     * positions for the deceleration -safe_stop_rate * qd (1/s), within the torque and rate limits. */
    float safe_stop_rate;
} arm_ctl_config_t;

typedef struct {
    float q[ARM_N_JOINTS];
    float qd[ARM_N_JOINTS];
    float q_d[ARM_N_JOINTS];
    float qd_d[ARM_N_JOINTS];
    float qdd_d[ARM_N_JOINTS];
    uint32_t fresh_mask; /* bit i: joint i's state arrived this period */
    float tau_measured[ARM_N_JOINTS]; /* the torque each drive reports it applies (end of last period) */
    /* bit i: joint i's torque is tau_override[i], open loop, instead of the method's (still through
     * the torque and rate limits); commissioning's pulses (arm/commission.h). 0: none */
    uint32_t torque_override_mask;
    float tau_override[ARM_N_JOINTS];
} arm_ctl_input_t;

typedef struct {
    float tau[ARM_N_JOINTS]; /* what goes to the drives, after the safety layer */
    /* internals, for telemetry */
    float e[ARM_N_JOINTS];
    float e_dot[ARM_N_JOINTS];
    float w_hat[ARM_N_JOINTS];
    float u_o[ARM_N_JOINTS];
    float tau_method[ARM_N_JOINTS]; /* before limits */
    uint32_t saturated_mask;        /* bit i: joint i's torque or rate was limited */
    arm_state_t state;
    arm_fault_t fault;
    int fault_joint;    /* 0-based joint of a plausibility fault, -1 otherwise */
    float fault_value;  /* what was measured (rad, rad/s, Nm) */
} arm_ctl_output_t;

typedef struct {
    const arm_robot_model_t *model;
    int rnea_kernel;    /* the model is the generated kernel's (arm_rnea_kernel.h): use it */
    arm_ctl_config_t cfg;
    union {
        arm_pm_t pm;
        arm_tde_t tde;
        arm_usde_smc_t usde_smc;
    } m;
    arm_state_t state;
    arm_fault_t fault;
    uint32_t stale_periods;
    float last_q[ARM_N_JOINTS];
    float last_qd[ARM_N_JOINTS];
    float tau_prev[ARM_N_JOINTS];
    /* The last commands, a ring (no copying a period): the command of k + 1 periods ago is
     * tau_sent[(sent_head + k) % ARM_TORQUE_REPORT_LAG_MAX]. */
    float tau_sent[ARM_TORQUE_REPORT_LAG_MAX][ARM_N_JOINTS];
    uint32_t sent_head;
    uint32_t n_sent;                        /* commands in tau_sent, at most ARM_TORQUE_REPORT_LAG_MAX */
    int have_last;                          /* last_q/last_qd hold a fresh sample of the last period */
    uint32_t mismatch_periods[ARM_N_JOINTS];
    int fault_joint;
    float fault_value;
} arm_ctl_t;

typedef enum {
    ARM_CTL_OK = 0,
    ARM_CTL_BAD_METHOD,
    ARM_CTL_BAD_PERIOD,
    ARM_CTL_BAD_GAIN,
    ARM_CTL_BAD_LIMIT, /* torque or torque-rate limit */
    ARM_CTL_BAD_DESIGN_RATE, /* the synthesised design was discretised for another loop rate */
    ARM_CTL_BAD_NUMERIC,
    ARM_CTL_BAD_RANGE,           /* q_min >= q_max */
    ARM_CTL_BAD_VELOCITY_LIMIT,
    ARM_CTL_BAD_FOLLOWING_LIMIT,
    ARM_CTL_BAD_MISMATCH_LIMIT,  /* torque_mismatch_limit or torque_mismatch_periods */
    ARM_CTL_BAD_STEP_TOLERANCE,
    ARM_CTL_BAD_DESIGN,          /* the design does not fit this firmware (arm_pm_design_fits) */
} arm_ctl_init_result_t;

/* Fills cfg with the defaults for the model (the numbers are the registry's,
 * firmware/params/params.toml): PD at 20 rad/s, critically damped; the model's
 * torque limits; a rate limit of full scale per 10 ms; a safe stop that holds the arm (gravity
 * compensation, damping at 20 1/s) after 3 stale periods;
 * every plausibility check: the model's joint ranges + 0.1 rad, 2 pi rad/s, steps within 0.01 rad
 * of what the velocities explain, 0.5 rad of following error, and the reported torque within 10 %
 * of the torque limit of the commanded one for no more than 3 periods in a row. */
void arm_ctl_default_config(const arm_robot_model_t *model, arm_ctl_config_t *cfg);
/* The plausible joint range: the model's widened by margin (rad); an unlimited joint stays so. */
void arm_ctl_joint_range(const arm_robot_model_t *model, float margin, float q_min[ARM_N_JOINTS],
                         float q_max[ARM_N_JOINTS]);
arm_ctl_init_result_t arm_ctl_init(arm_ctl_t *ctl, const arm_robot_model_t *model,
                                   const arm_ctl_config_t *cfg);
const char *arm_ctl_init_result_str(arm_ctl_init_result_t r);

void arm_ctl_step(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out);

/* The port detected a fault the core cannot see (lost peer, drive fault): latch safe stop. */
void arm_ctl_external_fault(arm_ctl_t *ctl);
/* A stop without a fault (a stop signal, the end of a run): safe stop from the next step on, the
 * arm held as after a fault. */
void arm_ctl_stop(arm_ctl_t *ctl);

const char *arm_state_str(arm_state_t s);
const char *arm_fault_str(arm_fault_t f);
const char *arm_method_str(arm_method_t m);
/* Returns ARM_METHOD_COUNT if the name is unknown. */
arm_method_t arm_method_from_str(const char *name);

#endif
