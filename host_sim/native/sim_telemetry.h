/* The simulator's telemetry on LCM: the truth per period (ARM_SIM: q, qd, the applied torque,
 * the true w) and events (ARM_SIM_EVENT). Published from the loop: an encode and one datagram
 * on loopback, a few microseconds, and nothing to hand over to another thread. */
#ifndef ARM_SIM_TELEMETRY_H
#define ARM_SIM_TELEMETRY_H

#include <stdint.h>

#include "lcm_sink.h"

typedef struct sim_telemetry sim_telemetry_t;

/* url "" : no telemetry (counts stay 0). NULL with a message in err on failure. */
sim_telemetry_t *sim_telemetry_open(const char *url, char *err, unsigned long errcap);
/* Software in the loop: into sink (shared with the controller, not closed here). */
sim_telemetry_t *sim_telemetry_open_sink(lcm_sink_t *sink, char *err, unsigned long errcap);
void sim_telemetry_truth(sim_telemetry_t *t, int64_t step, double period_s, int n, const double *q,
                         const double *qd, const double *tau, const double *w, int32_t drive_faults, int32_t flags);
void sim_telemetry_event(sim_telemetry_t *t, int64_t step, const char *source, const char *level,
                         const char *text);
uint64_t sim_telemetry_sent_truth(const sim_telemetry_t *t);
uint64_t sim_telemetry_sent_events(const sim_telemetry_t *t);
uint64_t sim_telemetry_errors(const sim_telemetry_t *t);
void sim_telemetry_close(sim_telemetry_t *t);

#endif
