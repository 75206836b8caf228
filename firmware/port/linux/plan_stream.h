/* --task stream: a planner's reference over LCM (channel ARM_PLAN, armlcm.plan_t), read without
 * waiting once a period. Its own UDP socket on the URL's group (on lo, TTL 0 as every LCM URL
 * here), LCM's UDPM wire format read directly (one "LC02" datagram a message, as the telemetry
 * logger reads it), decoded into fixed-size arrays: nothing is allocated in the loop. Linux only. */
#ifndef ARM_PLAN_STREAM_H
#define ARM_PLAN_STREAM_H

#include <stdint.h>

#include "arm/robot_model.h"

typedef struct {
    int64_t seq;
    int8_t n;
    float q[ARM_N_JOINTS], qd[ARM_N_JOINTS], qdd[ARM_N_JOINTS];
} plan_point_t;

typedef struct {
    int fd;
    uint64_t received;   /* ARM_PLAN messages decoded */
    uint64_t undecodable; /* ARM_PLAN datagrams that are not a plan_t (another type, truncated, bad n) */
    uint64_t other;       /* datagrams of other channels or formats (LC03 fragments): not ours */
} plan_stream_t;

/* 0, or -1 with a message naming --stream-url in err. */
int plan_stream_open(plan_stream_t *s, const char *url, char *err, unsigned long errcap);
/* Reads every queued datagram; the newest plan in *out. 1 when one came since the last call, 0 when
 * none did (out untouched). */
int plan_stream_poll(plan_stream_t *s, plan_point_t *out);
void plan_stream_close(plan_stream_t *s);

#endif
