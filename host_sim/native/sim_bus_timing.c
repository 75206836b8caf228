#include "sim_bus_timing.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

void sim_timeline_init(sim_timeline_t *tl)
{
    memset(tl, 0, sizeof(*tl));
}

void sim_timeline_new_period(sim_timeline_t *tl, double period_s)
{
    const double backlog = tl->free - period_s;
    if (backlog > tl->stats.backlog_max_s) {
        tl->stats.backlog_max_s = backlog;
    }
    tl->free = backlog > 0.0 ? backlog : 0.0;
}

void sim_timeline_transmit(sim_timeline_t *tl, double ready, const uint32_t *ids, unsigned n, double *ends)
{
    unsigned order[SIM_BATCH_MAX];
    if (n > SIM_BATCH_MAX) {
        n = SIM_BATCH_MAX;
    }
    for (unsigned i = 0; i < n; ++i) { /* insertion sort by id: arbitration order */
        unsigned k = i;
        while (k > 0u && ids[order[k - 1u]] > ids[i]) {
            order[k] = order[k - 1u];
            --k;
        }
        order[k] = i;
    }
    double t = tl->free > ready ? tl->free : ready;
    for (unsigned k = 0; k < n; ++k) {
        const uint32_t id = ids[order[k]];
        t += id < SIM_CAN_IDS ? tl->frame_s[id] : 0.0;
        ends[order[k]] = t;
    }
    tl->free = t;
}

int sim_timeline_parse_frames(sim_timeline_t *tl, const char *text)
{
    const char *p = text;
    while (*p != '\0') {
        char *end = NULL;
        errno = 0;
        const unsigned long id = strtoul(p, &end, 0);
        if (errno != 0 || end == p || *end != ':' || id >= SIM_CAN_IDS) {
            return -1;
        }
        p = end + 1;
        const double us = strtod(p, &end);
        if (end == p || !isfinite(us) || us < 0.0 || us > 1e6 || (*end != ',' && *end != '\0')) {
            return -1;
        }
        tl->frame_s[id] = us * 1e-6;
        p = *end == ',' ? end + 1 : end;
    }
    return 0;
}
