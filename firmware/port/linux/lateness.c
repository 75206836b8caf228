#include "lateness.h"

#include <stdio.h>
#include <string.h>

void lateness_init(lateness_t *lt)
{
    memset(lt, 0, sizeof(*lt));
}

static late_period_t *current(lateness_t *lt)
{
    return lt->n > 0u ? &lt->ring[(lt->n - 1u) % LATE_RING] : NULL;
}

const late_period_t *lateness_at(const lateness_t *lt, uint32_t k)
{
    return k < lt->n && k < LATE_RING ? &lt->ring[(lt->n - 1u - k) % LATE_RING] : NULL;
}

static int32_t us_of(int64_t ns)
{
    const int64_t us = ns / 1000;
    return us > INT32_MAX ? INT32_MAX : us < -INT32_MAX ? -INT32_MAX : (int32_t)us;
}

late_side_t lateness_judge(const late_period_t *p, int32_t *by_us)
{
    *by_us = 0;
    if (p->missing == 0u) return LATE_NONE;
    /* its own lateness took at least as long as it left the plant */
    if (p->wake_us >= p->wait_us) {
        *by_us = p->wake_us;
        return LATE_CONTROLLER;
    }
    if (p->late_sent_us >= 0) {
        if (p->late_sent_us <= p->wait_us) { /* sent in time, read after the wait: it was not running */
            *by_us = p->late_read_us - p->wait_us;
            return LATE_CONTROLLER;
        }
        *by_us = p->late_sent_us;
        return LATE_PLANT;
    }
    if (p->late_read_us >= 0) { /* came later; the transport does not say when it was sent */
        *by_us = p->late_read_us;
        return LATE_PLANT;
    }
    if (p->tx_lost > 0u || p->rx_dropped > 0u) return LATE_BUS; /* lost on the way */
    *by_us = -1;                                                 /* never answered */
    return LATE_PLANT;
}

const char *lateness_side_name(late_side_t side)
{
    switch (side) {
    case LATE_PLANT: return "the plant's answer";
    case LATE_CONTROLLER: return "the controller's wake-up";
    case LATE_BUS: return "the bus";
    default: return "none";
    }
}

static void settle(lateness_t *lt, late_period_t *p)
{
    p->side = lateness_judge(p, &p->by_us);
    if (p->side == LATE_NONE) return;
    lt->count[p->side]++;
    if (p->by_us > lt->worst_us[p->side]) lt->worst_us[p->side] = p->by_us;
}

static void bus_counts(late_period_t *p, uint64_t tx_lost, uint64_t rx_dropped)
{
    p->tx_lost = (uint32_t)(tx_lost - p->tx_start);
    p->rx_dropped = (uint32_t)(rx_dropped - p->rx_start);
}

void lateness_begin(lateness_t *lt, uint32_t period, int64_t wake_ns, int64_t sync_ns, double sync_sent_s,
                    int64_t wait_ns, uint64_t tx_lost, uint64_t rx_dropped)
{
    late_period_t *prev = current(lt);
    if (prev != NULL) {
        bus_counts(prev, tx_lost, rx_dropped);
        settle(lt, prev);
    }
    late_period_t *p = &lt->ring[lt->n % LATE_RING];
    *p = (late_period_t){.period = period, .wake_us = us_of(wake_ns), .wait_us = us_of(wait_ns), .last_us = -1,
                         .late_read_us = -1, .late_sent_us = -1, .tx_start = tx_lost, .rx_start = rx_dropped,
                         .sync_ns = sync_ns, .sync_sent_s = sync_sent_s};
    lt->n++;
}

void lateness_state(lateness_t *lt, int64_t now_ns, double sent_s, unsigned back)
{
    late_period_t *p = current(lt);
    if (p == NULL) return;
    if (back == 0u) {
        const int32_t at = us_of(now_ns - p->sync_ns);
        if (at > p->last_us) p->last_us = at;
        return;
    }
    late_period_t *before = (late_period_t *)lateness_at(lt, back - 1u);
    if (before == NULL) return;
    const int32_t read = us_of(now_ns - before->sync_ns);
    if (read > before->late_read_us) before->late_read_us = read;
    if (sent_s >= 0.0 && before->sync_sent_s >= 0.0) {
        const int32_t sent = us_of((int64_t)((sent_s - before->sync_sent_s) * 1e9));
        if (sent > before->late_sent_us) before->late_sent_us = sent;
    }
}

void lateness_missing(lateness_t *lt, uint32_t missing)
{
    late_period_t *p = current(lt);
    if (p != NULL) p->missing = missing;
}

late_side_t lateness_explain(lateness_t *lt, uint32_t skip, uint32_t periods, uint64_t tx_lost, uint64_t rx_dropped,
                             char *out, size_t cap)
{
    if (current(lt) != NULL) bus_counts(current(lt), tx_lost, rx_dropped);
    uint32_t count[LATE_SIDES] = {0};
    int32_t lo[LATE_SIDES], hi[LATE_SIDES], wake_max = 0, wait_min = INT32_MAX;
    uint32_t first = 0u, last = 0u;
    for (unsigned s = 0; s < LATE_SIDES; ++s) {
        lo[s] = INT32_MAX;
        hi[s] = -1;
    }
    for (uint32_t k = skip; k < skip + periods; ++k) {
        const late_period_t *p = lateness_at(lt, k);
        if (p == NULL) break;
        int32_t by = 0;
        const late_side_t side = lateness_judge(p, &by);
        if (p->wake_us > wake_max) wake_max = p->wake_us;
        if (side == LATE_NONE) continue;
        if (p->wait_us < wait_min) wait_min = p->wait_us;
        count[side]++;
        if (by >= 0 && by < lo[side]) lo[side] = by;
        if (by > hi[side]) hi[side] = by;
        if (last == 0u) last = p->period;
        first = p->period;
    }
    late_side_t side = LATE_PLANT;
    for (unsigned s = LATE_PLANT; s < LATE_SIDES; ++s) {
        if (count[s] > count[side]) side = (late_side_t)s;
    }
    const uint32_t total = count[LATE_PLANT] + count[LATE_CONTROLLER] + count[LATE_BUS];
    if (total == 0u) {
        snprintf(out, cap, "late: no period of the last %u missed its states", periods);
        return LATE_NONE;
    }
    int n = snprintf(out, cap, "late: %s in %u of the %u periods %u-%u that missed their states", lateness_side_name(side),
                     count[side], total, first, last);
    if (n < 0 || (size_t)n >= cap) return side;
    const double lo_ms = lo[side] == INT32_MAX ? -1.0 : lo[side] * 1e-3, hi_ms = hi[side] * 1e-3;
    if (side == LATE_PLANT && hi[side] < 0) {
        n += snprintf(out + n, cap - (size_t)n, " (no answer at all)");
    } else if (side == LATE_PLANT) {
        n += snprintf(out + n, cap - (size_t)n, " (answered %.2f-%.2f ms after SYNC; the controller waits %.2f ms)", lo_ms,
                      hi_ms, wait_min * 1e-3);
    } else if (side == LATE_CONTROLLER) {
        n += snprintf(out + n, cap - (size_t)n, " (it woke or read %.2f-%.2f ms late)", lo_ms, hi_ms);
    } else {
        n += snprintf(out + n, cap - (size_t)n, " (frames it could not send, or the kernel dropped)");
    }
    if (n > 0 && (size_t)n < cap && side != LATE_CONTROLLER) {
        (void)snprintf(out + n, cap - (size_t)n, "; the controller woke at most %.2f ms late", wake_max * 1e-3);
    }
    return side;
}
