/* The task's part of arm_controller's summary ("task": what it did; "commission": each joint's
 * measurements, which armctl commission judges against the model). */
#ifndef ARM_TASK_SUMMARY_H
#define ARM_TASK_SUMMARY_H

#include <stdio.h>

#include "options.h"
#include "task.h"

/* Writes `  "task": {...},\n` (and the commission's measurements) into an open summary. */
void task_summary_write(FILE *f, const options_t *opt, const task_report_t *r);

#endif
