/* Telemetry that never blocks the control loop: the loop copies a snapshot into a single-producer
 * single-consumer ring; a lower-priority thread encodes and publishes it on LCM. */
#ifndef ARM_TELEMETRY_H
#define ARM_TELEMETRY_H

#include <stdint.h>

#include "arm/controller.h"
#include "lcm_sink.h"

typedef enum { TELEM_CONTROLLER = 0, TELEM_TIMING, TELEM_EVENT, TELEM_KIND_COUNT } telem_kind_t;

typedef struct {
    int64_t step;
    int64_t bus_period;
    double t;
    int8_t method;
    float q[ARM_N_JOINTS];
    float qd[ARM_N_JOINTS];
    float q_d[ARM_N_JOINTS];
    arm_ctl_output_t out;
} telem_controller_t;

typedef struct {
    int64_t step;
    int32_t period_ns;
    int32_t wake_latency_ns;
    int32_t compute_ns;
    int32_t cycle_ns;
    int64_t overruns;
} telem_timing_t;

typedef struct {
    int64_t step;
    char level[8];
    char text[160];
} telem_event_t;

typedef struct telemetry telemetry_t;

/* Starts the publisher thread. url: an LCM provider URL (must keep TTL 0), or NULL/"" for none:
 * then snapshots are counted and discarded. Returns NULL with a message in err on failure. */
telemetry_t *telemetry_start(const char *url, char *err, unsigned long errcap);
/* Non-blocking; a full ring drops the message (counted) and its sequence number stays used,
 * so the loss is visible as a gap in the log. */
void telemetry_controller(telemetry_t *t, const telem_controller_t *m);
void telemetry_timing(telemetry_t *t, const telem_timing_t *m);
void telemetry_event(telemetry_t *t, int64_t step, const char *level, const char *text);
/* Software in the loop: no thread; every message goes to sink (shared, not closed here) as it is
 * made, in the loop's own thread. */
telemetry_t *telemetry_start_inline(lcm_sink_t *sink, char *err, unsigned long errcap);
/* The next message of kind gets sequence number seq (a relay of another controller's telemetry, the
 * PIL bridge, keeps that controller's numbers, and so its gaps). */
void telemetry_resequence(telemetry_t *t, telem_kind_t kind, uint64_t seq);
/* Publishes what is queued, stops the thread. */
void telemetry_stop(telemetry_t *t);

uint64_t telemetry_sent(const telemetry_t *t, telem_kind_t kind);     /* sequence numbers used */
uint64_t telemetry_published(const telemetry_t *t, telem_kind_t kind);
uint64_t telemetry_dropped(const telemetry_t *t);

#endif
