#define _GNU_SOURCE
#include "sim_capture.h"

#include <errno.h>
#include <math.h>
#include <string.h>
#include <time.h>

#define CAPTURE_BUFFER (1u << 20) /* a big stdio buffer: one write every few thousand frames */

static const char HEX[] = "0123456789ABCDEF";

int sim_capture_open(sim_capture_t *c, const char *path, int wall_clock, char *err, unsigned long errcap)
{
    memset(c, 0, sizeof(*c));
    c->wall = wall_clock;
    if (path[0] == '\0') return 0;
    c->f = fopen(path, "w");
    if (c->f == NULL) {
        snprintf(err, errcap, "--capture: cannot create '%s': %s", path, strerror(errno));
        return -1;
    }
    setvbuf(c->f, NULL, _IOFBF, CAPTURE_BUFFER);
    return 0;
}

void sim_capture_frame(sim_capture_t *c, double t_sim, unsigned bus, const arm_can_frame_t *f)
{
    if (c->f == NULL) return;
    double t = t_sim;
    if (c->wall) {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        t = (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
    }
    if (t < c->last + 1e-6) t = c->last + 1e-6; /* strictly increasing: replay keeps the order */
    c->last = t;
    const int ext = (f->flags & ARM_CAN_FLAG_EXT) != 0u;
    char line[48 + 2 * ARM_CAN_MAX_DATA];
    /* By hand, as "(%.6f) can%u %03X#..." would print it: snprintf per byte and per frame was
     * half of a captured run's time. t is whole microseconds plus rounding error, far from a half. */
    const long long us = llround(t * 1e6);
    int n = snprintf(line, sizeof(line), "(%lld.%06lld) can%u ", us / 1000000, us % 1000000, bus);
    for (int shift = ext ? 28 : 8; shift >= 0; shift -= 4) line[n++] = HEX[(f->id >> shift) & 0xFu];
    line[n++] = '#';
    if ((f->flags & ARM_CAN_FLAG_FD) != 0u) {
        const unsigned flags = ((f->flags & ARM_CAN_FLAG_BRS) ? 1u : 0u) | ((f->flags & ARM_CAN_FLAG_ESI) ? 2u : 0u);
        line[n++] = '#';
        line[n++] = HEX[flags];
    } else if ((f->flags & ARM_CAN_FLAG_RTR) != 0u) {
        line[n++] = 'R';
    }
    const unsigned len = f->len <= ARM_CAN_MAX_DATA ? f->len : ARM_CAN_MAX_DATA;
    for (unsigned i = 0; i < len && (f->flags & ARM_CAN_FLAG_RTR) == 0u; ++i) {
        line[n++] = HEX[f->data[i] >> 4];
        line[n++] = HEX[f->data[i] & 0xFu];
    }
    line[n++] = '\n';
    if (fwrite(line, 1, (size_t)n, c->f) != (size_t)n) c->failed = 1;
    c->frames++;
}

int sim_capture_close(sim_capture_t *c, const char *path, char *err, unsigned long errcap)
{
    if (c->f == NULL) return 0;
    const int bad = fclose(c->f) != 0 || c->failed;
    c->f = NULL;
    if (bad) {
        snprintf(err, errcap, "--capture: '%s' could not be written completely (disk full?)", path);
        return -1;
    }
    return 0;
}
