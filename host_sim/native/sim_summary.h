/* The simulator's run summary (JSON, written atomically) and its exit code (sim_main.c's header
 * lists them). */
#ifndef ARM_SIM_SUMMARY_H
#define ARM_SIM_SUMMARY_H

#include "sim_loop.h"
#include "sim_options.h"

int sim_write_summary(const char *path, const sim_options_t *o, const sim_arm_t *arm, const sim_report_t *r,
                      const sim_telemetry_t *tel, int locked, char *err, unsigned long errcap);
int sim_exit_code(const sim_report_t *r);

#endif
