#define _GNU_SOURCE
#include "telemetry.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "armlcm_controller_t.h"
#include "armlcm_event_t.h"
#include "armlcm_timing_t.h"
#include "lcm_sink.h"

#define RING_SIZE 4096u /* power of two; ~4 s of 1 kHz data if the publisher stalls */

typedef struct {
    telem_kind_t kind;
    int64_t seq;
    union {
        telem_controller_t ctl;
        telem_timing_t timing;
        telem_event_t event;
    } u;
} telem_slot_t;

struct telemetry {
    lcm_sink_t *sink; /* NULL: counted and discarded */
    int owns_sink;
    int inline_publish; /* one thread (software in the loop): publish at once, no publisher thread */
    pthread_t thread;
    atomic_bool running;
    atomic_uint_fast64_t head; /* written by the loop */
    atomic_uint_fast64_t tail; /* written by the publisher */
    uint64_t seq[TELEM_KIND_COUNT];
    atomic_uint_fast64_t published[TELEM_KIND_COUNT];
    atomic_uint_fast64_t dropped;
    telem_slot_t ring[RING_SIZE];
    uint8_t buf[4096]; /* encode buffer: the publisher owns it, so no allocation per message */
};

static telem_slot_t *claim(telemetry_t *t, telem_kind_t kind)
{
    const int64_t seq = (int64_t)t->seq[kind]++;
    const uint64_t head = atomic_load_explicit(&t->head, memory_order_relaxed);
    const uint64_t tail = atomic_load_explicit(&t->tail, memory_order_acquire);
    if (head - tail >= RING_SIZE) {
        atomic_fetch_add_explicit(&t->dropped, 1u, memory_order_relaxed);
        return NULL;
    }
    telem_slot_t *s = &t->ring[head & (RING_SIZE - 1u)];
    s->kind = kind;
    s->seq = seq;
    return s;
}

static void publish(telemetry_t *t, const telem_slot_t *s);

static void commit(telemetry_t *t)
{
    const uint64_t head = atomic_fetch_add_explicit(&t->head, 1u, memory_order_release);
    if (t->inline_publish) {
        publish(t, &t->ring[head & (RING_SIZE - 1u)]);
        atomic_store_explicit(&t->tail, head + 1u, memory_order_release);
    }
}

void telemetry_controller(telemetry_t *t, const telem_controller_t *m)
{
    telem_slot_t *s = claim(t, TELEM_CONTROLLER);
    if (s != NULL) {
        s->u.ctl = *m;
        commit(t);
    }
}

void telemetry_timing(telemetry_t *t, const telem_timing_t *m)
{
    telem_slot_t *s = claim(t, TELEM_TIMING);
    if (s != NULL) {
        s->u.timing = *m;
        commit(t);
    }
}

void telemetry_event(telemetry_t *t, int64_t step, const char *level, const char *text)
{
    telem_slot_t *s = claim(t, TELEM_EVENT);
    if (s != NULL) {
        s->u.event.step = step;
        snprintf(s->u.event.level, sizeof(s->u.event.level), "%s", level);
        snprintf(s->u.event.text, sizeof(s->u.event.text), "%s", text);
        commit(t);
    }
}

static void publish(telemetry_t *t, const telem_slot_t *s)
{
    int len = -1;
    const char *channel = "";
    if (s->kind == TELEM_CONTROLLER) {
        const telem_controller_t *c = &s->u.ctl;
        armlcm_controller_t m = {
            .seq = s->seq,
            .step = c->step,
            .bus_period = c->bus_period,
            .t = c->t,
            .method = c->method,
            .state = (int8_t)c->out.state,
            .fault = (int8_t)c->out.fault,
            .saturated_mask = (int32_t)c->out.saturated_mask,
            .n = ARM_N_JOINTS,
            .q = (float *)c->q,
            .qd = (float *)c->qd,
            .q_d = (float *)c->q_d,
            .e = (float *)c->out.e,
            .e_dot = (float *)c->out.e_dot,
            .w_hat = (float *)c->out.w_hat,
            .u_o = (float *)c->out.u_o,
            .tau = (float *)c->out.tau,
        };
        channel = "ARM_CTL";
        len = armlcm_controller_t_encode(t->buf, 0, (int)sizeof(t->buf), &m);
    } else if (s->kind == TELEM_TIMING) {
        const telem_timing_t *c = &s->u.timing;
        armlcm_timing_t m = {
            .seq = s->seq,
            .step = c->step,
            .period_ns = c->period_ns,
            .wake_latency_ns = c->wake_latency_ns,
            .compute_ns = c->compute_ns,
            .cycle_ns = c->cycle_ns,
            .overruns = c->overruns,
            .telemetry_dropped = (int64_t)atomic_load(&t->dropped),
        };
        channel = "ARM_TIMING";
        len = armlcm_timing_t_encode(t->buf, 0, (int)sizeof(t->buf), &m);
    } else {
        const telem_event_t *c = &s->u.event;
        armlcm_event_t m = {
            .seq = s->seq,
            .step = c->step,
            .source = (char *)"controller",
            .level = (char *)c->level,
            .text = (char *)c->text,
        };
        channel = "ARM_EVENT";
        len = armlcm_event_t_encode(t->buf, 0, (int)sizeof(t->buf), &m);
    }
    if (len > 0 && t->sink != NULL && lcm_sink_publish(t->sink, channel, t->buf, (unsigned)len) == 0) {
        atomic_fetch_add(&t->published[s->kind], 1u);
    }
}

static void *publisher(void *arg)
{
    telemetry_t *t = arg;
    const struct timespec idle = {.tv_sec = 0, .tv_nsec = 200000};
    for (;;) {
        const uint64_t tail = atomic_load_explicit(&t->tail, memory_order_relaxed);
        const uint64_t head = atomic_load_explicit(&t->head, memory_order_acquire);
        if (tail == head) {
            if (!atomic_load(&t->running)) {
                break;
            }
            nanosleep(&idle, NULL);
            continue;
        }
        publish(t, &t->ring[tail & (RING_SIZE - 1u)]);
        atomic_store_explicit(&t->tail, tail + 1u, memory_order_release);
    }
    return NULL;
}

telemetry_t *telemetry_start(const char *url, char *err, unsigned long errcap)
{
    telemetry_t *t = calloc(1, sizeof(*t)); /* start-up only; the loop never allocates */
    if (t == NULL) {
        snprintf(err, errcap, "telemetry: out of memory");
        return NULL;
    }
    if (url != NULL && url[0] != '\0') {
        t->sink = lcm_sink_open_url(url, err, errcap);
        if (t->sink == NULL) {
            free(t);
            return NULL;
        }
        t->owns_sink = 1;
    }
    atomic_store(&t->running, true);
    if (pthread_create(&t->thread, NULL, publisher, t) != 0) {
        snprintf(err, errcap, "telemetry: cannot start the publisher thread");
        lcm_sink_close(t->sink);
        free(t);
        return NULL;
    }
    return t;
}

telemetry_t *telemetry_start_inline(lcm_sink_t *sink, char *err, unsigned long errcap)
{
    telemetry_t *t = calloc(1, sizeof(*t));
    if (t == NULL) {
        snprintf(err, errcap, "telemetry: out of memory");
        return NULL;
    }
    t->sink = sink;
    t->inline_publish = 1;
    return t;
}

void telemetry_stop(telemetry_t *t)
{
    if (t == NULL) {
        return;
    }
    if (!t->inline_publish) {
        atomic_store(&t->running, false);
        pthread_join(t->thread, NULL);
    }
    if (t->owns_sink) {
        lcm_sink_close(t->sink);
    }
    /* Counters stay readable: the caller frees with free() after reading them. */
}

void telemetry_resequence(telemetry_t *t, telem_kind_t kind, uint64_t seq)
{
    t->seq[kind] = seq;
}

uint64_t telemetry_sent(const telemetry_t *t, telem_kind_t kind)
{
    return t->seq[kind];
}

uint64_t telemetry_published(const telemetry_t *t, telem_kind_t kind)
{
    return atomic_load(&((telemetry_t *)t)->published[kind]);
}

uint64_t telemetry_dropped(const telemetry_t *t)
{
    return atomic_load(&((telemetry_t *)t)->dropped);
}
