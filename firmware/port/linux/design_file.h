/* --design-file: a design (arm_pm_design_t) read at run time from the text file gen.synth writes
 * next to the headers (pm_design.txt, gen/synth/emit.py design_file), so a software-in-the-loop
 * run of a tuning or a study needs no firmware build per design. No heap: the tables live in this
 * struct, sized for the largest design the build runs (ARM_PM_*_NX_MAX). */
#ifndef ARM_DESIGN_FILE_H
#define ARM_DESIGN_FILE_H

#include <stdint.h>

#include "arm/pm.h"

typedef struct {
    arm_pm_design_t d; /* points into the tables below */
    char path[512];    /* where it was read from (for messages) */
    float est_a[ARM_PM_EST_NX_MAX * ARM_PM_EST_NX_MAX], est_b[ARM_PM_EST_NX_MAX * 2], est_c[ARM_PM_EST_NX_MAX],
        est_d[2];
    float ctl_a[ARM_PM_CTL_NX_MAX * ARM_PM_CTL_NX_MAX], ctl_b[ARM_PM_CTL_NX_MAX * 2], ctl_c[ARM_PM_CTL_NX_MAX],
        ctl_d[2];
    float im_a[4], im_b[2];
    int32_t est_a_q[ARM_PM_EST_NX_MAX * ARM_PM_EST_NX_MAX], est_b_q[ARM_PM_EST_NX_MAX * 2],
        est_c_q[ARM_PM_EST_NX_MAX], est_d_q[2];
    int32_t ctl_a_q[ARM_PM_CTL_NX_MAX * ARM_PM_CTL_NX_MAX], ctl_b_q[ARM_PM_CTL_NX_MAX * 2],
        ctl_c_q[ARM_PM_CTL_NX_MAX], ctl_d_q[2];
    int32_t im_a_q[4], im_b_q[2];
} design_file_t;

/* Reads path into out. A file that is not exactly the format (every field, in order, with the
 * numbers its dimensions ask for) or a design this build cannot run (another joint count, more
 * states than ARM_PM_*_NX_MAX) fails with one line in err naming the file, line and field; -1. */
int design_file_load(const char *path, design_file_t *out, char *err, unsigned long errcap);

#endif
