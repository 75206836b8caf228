/* A short closed-loop run of the core's control step against a plant, identical on the host and on
 * the target: the golden sequence is produced by the host build (tests/c/gen_closed_loop_golden.c)
 * and checked on the Cortex-M image (main.c).
 *
 * Plant: the nominal rigid-body model itself (forward dynamics from the core's RNEA: M(q) column
 * by column, Cholesky solve), integrated semi-implicitly at the control period, plus a known
 * smooth matched disturbance (2 rad/s^2 added to each joint's acceleration) so the estimators have something to estimate. float32 throughout,
 * like the core. */
#ifndef ARM_CLOSED_LOOP_H
#define ARM_CLOSED_LOOP_H

#include <stdint.h>

#include "arm/controller.h"

#define CL_STEPS 300u      /* 0.3 s at 1 kHz */
#define CL_RECORD_EVERY 5u /* torques recorded every 5th step */
#define CL_RECORDS (CL_STEPS / CL_RECORD_EVERY)

typedef struct {
    arm_method_t method;
    arm_numeric_t numeric;
} cl_case_t;

/* Every method, float32; and the fixed-point variant of the methods that have one. */
#define CL_MAX_CASES 16
int cl_cases(cl_case_t cases[CL_MAX_CASES]);

typedef struct {
    int init_result;                            /* arm_ctl_init's result (0 = ok) */
    float tau[CL_RECORDS][ARM_N_JOINTS];        /* commanded torque, every CL_RECORD_EVERY steps */
    float q_final[ARM_N_JOINTS];
    uint32_t final_state;                       /* arm_state_t after the last step */
} cl_result_t;

/* Runs CL_STEPS periods of case c from the arm's home pose (ARM_HOME_Q of the generated model).
 * No heap, no OS. */
void cl_run(const arm_robot_model_t *model, const float home[ARM_N_JOINTS], const cl_case_t *c, cl_result_t *r);

#endif
