/* The paper's method: the generalized-H2 controller C (u_o) and the H-infinity disturbance
 * estimator K (w_hat), per joint, in float32 or int32 fixed point, chosen at run time. The design
 * (K, C and their fixed-point formats) is data, arm_pm_design_t: the one compiled into the
 * firmware (arm_pm_builtin_design, from the headers gen.synth emits, pm_design_float.h and
 * pm_design_fixed.h; const, so in flash on the MCU) or one a port loads at run time (the Linux
 * port's --design-file), run by the same code in the same operation order, so the same design
 * gives bit-identical results either way. */
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

/* Designs loaded at run time (the Linux port's --design-file): 1 where a port loads them, 0 where
 * only the built-in design runs (the MCU images: cortex_m's CMake sets 0), which then compiles
 * with its own dimensions alone (firmware/core/src/pm.c). */
#ifndef ARM_PM_RUNTIME_DESIGNS
#define ARM_PM_RUNTIME_DESIGNS 1
#endif

/* The largest state dimensions a design may have: the built-in design's, and, where designs are
 * loaded at run time, at least ARM_PM_NX_MIN_MAX, which holds every design the tuner makes (per
 * joint, F of first order: K has at most the plant's 2 states plus F's 1, C at most the plant's
 * 2). A larger design is refused (arm_pm_design_fits). Loops run to a design's own dimensions,
 * bounded by these. */
#if ARM_PM_RUNTIME_DESIGNS
#define ARM_PM_NX_MIN_MAX 4
#else
#define ARM_PM_NX_MIN_MAX 1
#endif
#if ARM_EST_NX > ARM_PM_NX_MIN_MAX
#define ARM_PM_EST_NX_MAX ARM_EST_NX
#else
#define ARM_PM_EST_NX_MAX ARM_PM_NX_MIN_MAX
#endif
#if ARM_CTL_NX > ARM_PM_NX_MIN_MAX
#define ARM_PM_CTL_NX_MAX ARM_CTL_NX
#else
#define ARM_PM_CTL_NX_MAX ARM_PM_NX_MIN_MAX
#endif
/* Every state array holds the larger: an update copies whole arrays (a fixed-size copy; one of a
 * design's own length is a memcpy call on the MCU). */
#define ARM_PM_NX_MAX (ARM_PM_EST_NX_MAX > ARM_PM_CTL_NX_MAX ? ARM_PM_EST_NX_MAX : ARM_PM_CTL_NX_MAX)

/* One per-joint design: exactly the numbers of pm_design_float.h and pm_design_fixed.h that the
 * firmware runs. Tables are row-major with the design's own dimensions (A nx x nx, B nx x 2,
 * C 1 x nx, D 1 x 2; the internal model A 2 x 2, B 2 x 1), floats and their int32 Q-format twins. */
typedef struct {
    char hash[17];      /* ARM_DESIGN_HASH: the manifest's content hash, 16 hex digits */
    int n_joints;       /* must be ARM_N_JOINTS */
    float loop_rate_hz; /* the rate it was discretised for (ARM_LOOP_RATE_HZ) */
    int est_nx, ctl_nx; /* 1..ARM_PM_EST_NX_MAX, 1..ARM_PM_CTL_NX_MAX */
    const float *est_a, *est_b, *est_c, *est_d;
    const float *ctl_a, *ctl_b, *ctl_c, *ctl_d;
    const float *im_a, *im_b;
    const int32_t *est_a_q, *est_b_q, *est_c_q, *est_d_q;
    const int32_t *ctl_a_q, *ctl_b_q, *ctl_c_q, *ctl_d_q;
    const int32_t *im_a_q, *im_b_q;
    int y_frac, est_u_frac, ctl_u_frac; /* ARM_Y_FRAC, ARM_EST_U_FRAC, ARM_CTL_U_FRAC */
    int est_acc_x_shift, est_acc_u_shift, ctl_acc_x_shift, ctl_acc_u_shift, im_acc_x_shift;
    int32_t range_e_max_q, range_e_dot_max_q; /* ARM_RANGE_E_MAX_Q, ARM_RANGE_E_DOT_MAX_Q */
    int32_t im_e_max_q, im_e_dot_max_q;       /* ARM_IM_E_MAX_Q, ARM_IM_E_DOT_MAX_Q */
} arm_pm_design_t;

/* The design compiled into this firmware (pm_design_*.h). */
extern const arm_pm_design_t arm_pm_builtin_design;

typedef enum { ARM_NUMERIC_FLOAT = 0, ARM_NUMERIC_FIXED } arm_numeric_t;

typedef enum {
    ARM_PM_DECOUPLED = 0, /* K acts on y - x_m, x_m the internal model driven by u_o (default) */
    ARM_PM_PAPER,         /* K acts on y, as printed in the paper */
    ARM_PM_NO_ESTIMATOR,  /* C alone, w_hat = 0 (the paper's Example 1) */
} arm_pm_structure_t;

typedef struct {
    const arm_pm_design_t *d;
    arm_numeric_t numeric;
    arm_pm_structure_t structure;
    int primed; /* the internal model starts at the first measurement, as the header says */
    union {
        struct {
            float est[ARM_N_JOINTS][ARM_PM_NX_MAX];
            float ctl[ARM_N_JOINTS][ARM_PM_NX_MAX];
            float im[ARM_N_JOINTS][2];
            float v[ARM_N_JOINTS][2]; /* the estimator's input this period */
            float y[ARM_N_JOINTS][2];
            float u_o[ARM_N_JOINTS];
        } f;
        struct {
            int32_t est[ARM_N_JOINTS][ARM_PM_NX_MAX];
            int32_t ctl[ARM_N_JOINTS][ARM_PM_NX_MAX];
            int32_t im[ARM_N_JOINTS][2];
            int32_t v[ARM_N_JOINTS][2];
            int32_t y[ARM_N_JOINTS][2];
            int32_t u_o[ARM_N_JOINTS];
        } q;
    } s;
} arm_pm_t;

/* design: one that arm_pm_design_fits (arm_ctl_init checks it); it must outlive pm. */
void arm_pm_init(arm_pm_t *pm, const arm_pm_design_t *design, arm_numeric_t numeric,
                 arm_pm_structure_t structure);

/* Outputs for this period from the current states (nothing is updated yet). */
void arm_pm_output(arm_pm_t *pm, const float e[ARM_N_JOINTS], const float e_dot[ARM_N_JOINTS],
                   float u_o[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS]);

/* Advances every state one period with this period's inputs. For joints in hold_mask (torque
 * limited this period) the estimator state is held and, in the decoupled structure, the internal
 * model is reset to the measured error: anti-windup, so K does not integrate the limiter's effect
 * as disturbance. */
void arm_pm_update(arm_pm_t *pm, uint32_t hold_mask);

/* 0 if this firmware can run the design: ARM_N_JOINTS joints, state dimensions within
 * ARM_PM_*_NX_MAX, every table given, shifts and formats in 0..62, and, without
 * ARM_PM_RUNTIME_DESIGNS, the built-in design itself; else -1 (arm_ctl_init refuses with
 * ARM_CTL_BAD_DESIGN). */
int arm_pm_design_fits(const arm_pm_design_t *design);
/* 0 if loop_rate_hz is the rate the design was discretised for (within 0.1 %), else -1
 * (arm_ctl_init refuses with ARM_CTL_BAD_DESIGN_RATE). */
int arm_pm_check_design(const arm_pm_design_t *design, float loop_rate_hz);

#endif
