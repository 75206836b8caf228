/* The record of the arm after the stop (--post-stop), which both loops keep the same way (sim_loop.c,
 * sim_canopen_loop.c run the arm on; this keeps what the summary says of it). */
#ifndef ARM_SIM_AFTER_STOP_H
#define ARM_SIM_AFTER_STOP_H

#include "sim_loop.h"

/* The arm runs on from here, for `why`: where it starts (q0, filled), when, and the event saying so.
 * Returns the periods to simulate. */
uint64_t sim_after_stop_begin(sim_report_t *rep, const sim_config_t *cfg, const sim_arm_t *arm, sim_telemetry_t *tel,
                              const char *why, double q0[SIM_MAX_JOINTS]);
/* One period simulated after the stop: each joint's largest motion from q0 so far. */
void sim_after_stop_period(sim_report_t *rep, const sim_arm_t *arm, const double q0[SIM_MAX_JOINTS]);
/* What joint j's drive ended in: its statusword, and whether its brake holds. */
void sim_after_stop_drive(sim_report_t *rep, int j, uint16_t statusword, int braked);

#endif
