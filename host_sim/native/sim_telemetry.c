#include "sim_telemetry.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armlcm_event_t.h"
#include "armlcm_sim_truth_t.h"
#include "lcm_sink.h"
#include "sim_arm.h"

struct sim_telemetry {
    lcm_sink_t *sink; /* NULL: no telemetry */
    int owns_sink;
    uint64_t sent_truth;
    uint64_t sent_events;
    uint64_t errors;
    uint8_t buf[4096];
};

sim_telemetry_t *sim_telemetry_open(const char *url, char *err, unsigned long errcap)
{
    sim_telemetry_t *t = calloc(1, sizeof(*t));
    if (t == NULL) {
        snprintf(err, errcap, "telemetry: out of memory");
        return NULL;
    }
    if (url[0] != '\0') {
        t->sink = lcm_sink_open_url(url, err, errcap);
        if (t->sink == NULL) {
            free(t);
            return NULL;
        }
        t->owns_sink = 1;
    }
    return t;
}

sim_telemetry_t *sim_telemetry_open_sink(lcm_sink_t *sink, char *err, unsigned long errcap)
{
    sim_telemetry_t *t = calloc(1, sizeof(*t));
    if (t == NULL) {
        snprintf(err, errcap, "telemetry: out of memory");
        return NULL;
    }
    t->sink = sink;
    return t;
}

static void publish(sim_telemetry_t *t, const char *channel, int len)
{
    if (len < 0 || lcm_sink_publish(t->sink, channel, t->buf, (unsigned)len) != 0) {
        t->errors++;
    }
}

void sim_telemetry_truth(sim_telemetry_t *t, int64_t step, double period_s, int n, const double *q,
                         const double *qd, const double *tau, const double *w, int32_t drive_faults, int32_t flags)
{
    if (t->sink == NULL) {
        return;
    }
    double cq[SIM_MAX_JOINTS], cqd[SIM_MAX_JOINTS], ctau[SIM_MAX_JOINTS], cw[SIM_MAX_JOINTS];
    memcpy(cq, q, (size_t)n * sizeof(double));
    memcpy(cqd, qd, (size_t)n * sizeof(double));
    memcpy(ctau, tau, (size_t)n * sizeof(double));
    memcpy(cw, w, (size_t)n * sizeof(double));
    armlcm_sim_truth_t m = {
        .seq = (int64_t)t->sent_truth++, .step = step, .t = (double)step * period_s, .n = (int16_t)n,
        .q = cq, .qd = cqd, .tau_applied = ctau, .w_true = cw, .drive_faults = drive_faults, .flags = flags,
    };
    publish(t, "ARM_SIM", armlcm_sim_truth_t_encode(t->buf, 0, (int)sizeof(t->buf), &m));
}

void sim_telemetry_event(sim_telemetry_t *t, int64_t step, const char *source, const char *level,
                         const char *text)
{
    if (t->sink == NULL) {
        return;
    }
    armlcm_event_t m = {.seq = (int64_t)t->sent_events++, .step = step, .source = (char *)source,
                        .level = (char *)level, .text = (char *)text};
    publish(t, "ARM_SIM_EVENT", armlcm_event_t_encode(t->buf, 0, (int)sizeof(t->buf), &m));
}

uint64_t sim_telemetry_sent_truth(const sim_telemetry_t *t) { return t->sent_truth; }
uint64_t sim_telemetry_sent_events(const sim_telemetry_t *t) { return t->sent_events; }
uint64_t sim_telemetry_errors(const sim_telemetry_t *t) { return t->errors; }

void sim_telemetry_close(sim_telemetry_t *t)
{
    if (t == NULL) return;
    if (t->owns_sink) lcm_sink_close(t->sink);
    free(t);
}
