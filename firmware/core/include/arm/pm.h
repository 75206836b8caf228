/* The paper's method: the generalized-H2 controller C (u_o) and the H-infinity disturbance
 * estimator K (w_hat), per joint, from the headers gen.synth emits (pm_design_float.h and
 * pm_design_fixed.h), in float32 or int32 fixed point, chosen at run time. */
#ifndef ARM_PM_H
#define ARM_PM_H

#include <stdint.h>

#include "arm/robot_model.h"
#include "pm_design_float.h" /* generated: dimensions and float tables */

#if ARM_DESIGN_N_JOINTS != ARM_N_JOINTS
#error "pm_design_float.h was synthesised for a different number of joints than the robot model"
#endif
#if ARM_DESIGN_PER_JOINT != 1 || ARM_EST_NY != 2 || ARM_EST_NU != 1 || ARM_CTL_NY != 2 || ARM_CTL_NU != 1
#error "the firmware runs per-joint designs (ARM_DESIGN_PER_JOINT 1, y = [e_j, e_dot_j])"
#endif

typedef enum { ARM_NUMERIC_FLOAT = 0, ARM_NUMERIC_FIXED } arm_numeric_t;

typedef enum {
    ARM_PM_DECOUPLED = 0, /* K acts on y - x_m, x_m the internal model driven by u_o (default) */
    ARM_PM_PAPER,         /* K acts on y, as printed in the paper */
    ARM_PM_NO_ESTIMATOR,  /* C alone, w_hat = 0 (the paper's Example 1) */
} arm_pm_structure_t;

typedef struct {
    arm_numeric_t numeric;
    arm_pm_structure_t structure;
    int primed; /* the internal model starts at the first measurement, as the header says */
    union {
        struct {
            float est[ARM_N_JOINTS][ARM_EST_NX];
            float ctl[ARM_N_JOINTS][ARM_CTL_NX];
            float im[ARM_N_JOINTS][2];
            float v[ARM_N_JOINTS][2]; /* the estimator's input this period */
            float y[ARM_N_JOINTS][2];
            float u_o[ARM_N_JOINTS];
        } f;
        struct {
            int32_t est[ARM_N_JOINTS][ARM_EST_NX];
            int32_t ctl[ARM_N_JOINTS][ARM_CTL_NX];
            int32_t im[ARM_N_JOINTS][2];
            int32_t v[ARM_N_JOINTS][2];
            int32_t y[ARM_N_JOINTS][2];
            int32_t u_o[ARM_N_JOINTS];
        } q;
    } s;
} arm_pm_t;

void arm_pm_init(arm_pm_t *pm, arm_numeric_t numeric, arm_pm_structure_t structure);

/* Outputs for this period from the current states (nothing is updated yet). */
void arm_pm_output(arm_pm_t *pm, const float e[ARM_N_JOINTS], const float e_dot[ARM_N_JOINTS],
                   float u_o[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS]);

/* Advances every state one period with this period's inputs. For joints in hold_mask (torque
 * limited this period) the estimator state is held and, in the decoupled structure, the internal
 * model is reset to the measured error: anti-windup, so K does not integrate the limiter's effect
 * as disturbance. */
void arm_pm_update(arm_pm_t *pm, uint32_t hold_mask);

/* The design's identity (ARM_DESIGN_HASH of the generated headers), for logs. */
const char *arm_pm_design_hash(void);
/* 0 if loop_rate_hz is the rate the design was discretised for (ARM_LOOP_RATE_HZ, within 0.1 %),
 * else -1 (arm_ctl_init refuses with ARM_CTL_BAD_DESIGN_RATE). */
int arm_pm_check_design(float loop_rate_hz);

#endif
