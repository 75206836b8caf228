/* The methods the control step can run, as plug-ins: one entry each in one table
 * (ARM_METHOD_TABLE in firmware/core/src/methods.c), which the step dispatches through and every
 * list of methods reads: the controller's --method and usage, the Cortex-M closed-loop images, the tests, and the
 * Python tools (tools/methods.py reads the table's names from methods.c). Adding a method is one
 * entry there (and its ARM_METHOD_* in controller.h), plus its tests: docs/firmware.md, Adding a method. */
#ifndef ARM_METHODS_H
#define ARM_METHODS_H

#include "arm/controller.h"

typedef struct {
    const char *name;  /* --method NAME, in run.json, the CLI, the report */
    int uses_design;   /* runs the synthesised K and/or C (pm_design_*.h): the loop rate must match */
} arm_method_ops_t;

/* The table's entry for m, or NULL if m is not a method. */
const arm_method_ops_t *arm_method_ops(arm_method_t m);

/* The method's calls, dispatched from the same table by a switch: direct calls, so the Cortex-M
 * build's static stack analysis bounds them (it refuses an indirect call). */
/* The method's state from the config (ctl->m). */
void arm_method_init(arm_ctl_t *ctl);
/* This period's u_o and w_hat from the method's state, e and e_dot (in out). */
void arm_method_output(arm_ctl_t *ctl, arm_ctl_output_t *out);
/* The state advanced; acc: the accelerations commanded, hold_mask: joints the safety layer
 * limited (their estimators hold). */
void arm_method_update(arm_ctl_t *ctl, const float acc[ARM_N_JOINTS], uint32_t hold_mask);

#endif
