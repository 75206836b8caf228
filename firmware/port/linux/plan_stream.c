#define _GNU_SOURCE
#include "plan_stream.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "arm/lcm_url.h"
#include "armlcm_plan_t.h"

#define CHANNEL "ARM_PLAN"
#define MAGIC_SHORT 0x4c433032u /* "LC02": a whole message in one datagram */
#define DGRAM_MAX 2048          /* a plan_t is 217 bytes; anything longer is not one */
#define READS_MAX 256           /* a period reads at most this many datagrams: a flood waits */

static uint32_t be32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

int plan_stream_open(plan_stream_t *s, const char *url, char *err, unsigned long errcap)
{
    memset(s, 0, sizeof(*s));
    s->fd = -1;
    arm_lcm_url_t u;
    if (arm_lcm_url_parse(url, "--stream-url", &u, err, errcap) != 0 ||
        arm_lcm_url_check_route(&u, "--stream-url", err, errcap) != 0) {
        return -1;
    }
    if (u.none) {
        snprintf(err, errcap, "--stream-url: a planner's LCM URL is needed for --task stream");
        return -1;
    }
    s->fd = arm_lcm_url_open_rx(&u, "--stream-url", url, 1 << 20, 1, err, errcap);
    return s->fd < 0 ? -1 : 0;
}

/* One datagram: 1 with the plan in *out, 0 if it is not one. */
static int decode(plan_stream_t *s, const uint8_t *buf, size_t n, plan_point_t *out)
{
    if (n < 8u + sizeof(CHANNEL) || be32(buf) != MAGIC_SHORT || memcmp(buf + 8, CHANNEL, sizeof(CHANNEL)) != 0) {
        s->other++;
        return 0;
    }
    const size_t at = 8u + sizeof(CHANNEL);
    armlcm_plan_t m;
    if (armlcm_plan_t_decode(buf + at, 0, (int)(n - at), &m) < 0 || m.n != ARM_N_JOINTS) {
        s->undecodable++;
        return 0;
    }
    out->seq = m.seq;
    out->n = m.n;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        out->q[j] = m.q_d[j];
        out->qd[j] = m.qd_d[j];
        out->qdd[j] = m.qdd_d[j];
    }
    s->received++;
    return 1;
}

int plan_stream_poll(plan_stream_t *s, plan_point_t *out)
{
    int got = 0;
    static uint8_t buf[DGRAM_MAX];
    for (int i = 0; i < READS_MAX && s->fd >= 0; ++i) {
        const ssize_t n = recv(s->fd, buf, sizeof(buf), MSG_DONTWAIT | MSG_TRUNC);
        if (n < 0) break; /* EAGAIN: nothing more queued (an error: the stream goes stale) */
        if ((size_t)n > sizeof(buf)) {
            s->other++;
            continue;
        }
        got |= decode(s, buf, (size_t)n, out);
    }
    return got;
}

void plan_stream_close(plan_stream_t *s)
{
    if (s->fd >= 0) close(s->fd);
    s->fd = -1;
}
