/* Which side was late when a period's joint states missed the controller's wait: the plant's
 * answer (the drives, or the simulator standing in for them), the controller's own wake-up (or its
 * reading, when the answers were in time but it was not running), or the bus (a frame it could not
 * send, or one the kernel dropped). Each period's timing is kept in a ring: when the controller
 * woke, how long after its SYNC it waited, when each state came (and, where the transport carries
 * it, when its sender sent it: arm_can_bus_set_sent_s), and what the bus lost. A period that missed
 * states is judged once the next period has read what came late (its drain), and counted by side;
 * a stop for lateness (the watchdog, a lockstep wait run out) names the side and by how much from
 * the periods that led to it. No heap, no OS: the MCU image's loop keeps one too. */
#ifndef ARM_LATENESS_H
#define ARM_LATENESS_H

#include <stddef.h>
#include <stdint.h>

typedef enum { LATE_NONE = 0, LATE_PLANT, LATE_CONTROLLER, LATE_BUS, LATE_SIDES } late_side_t;

typedef struct {
    uint32_t period;       /* bus period */
    int32_t wake_us;       /* the controller's wake-up latency (realtime; 0 in lockstep) */
    int32_t wait_us;       /* how long after its SYNC it waited for the states */
    int32_t last_us;       /* SYNC -> the last state read within the wait; -1: none */
    uint32_t missing;      /* joints whose state missed the wait */
    int32_t late_read_us;  /* SYNC -> when the controller read a missed state (the latest); -1: never */
    int32_t late_sent_us;  /* SYNC -> when its sender sent it (the transport's time); -1: unknown */
    uint32_t tx_lost;      /* this period's frames the bus could not take (SYNC, commands) */
    uint32_t rx_dropped;   /* frames the kernel dropped on a full receive queue meanwhile */
    uint64_t tx_start, rx_start; /* the bus's counts as it began */
    int64_t sync_ns;       /* the port's clock at SYNC */
    double sync_sent_s;    /* the transport's clock at SYNC (-1: none) */
    late_side_t side;      /* judged once the next period has drained */
    int32_t by_us;         /* how late that side was */
} late_period_t;

#define LATE_RING 16u

typedef struct {
    late_period_t ring[LATE_RING];
    uint32_t n;            /* periods begun */
    uint32_t count[LATE_SIDES]; /* periods that missed states, by side */
    int32_t worst_us[LATE_SIDES];
} lateness_t;

void lateness_init(lateness_t *lt);
/* Period `period` begins: its SYNC goes out now (sync_ns on the port's clock, sync_sent_s on the
 * transport's), after a wake-up wake_ns late; it waits for the states until wait_ns after SYNC.
 * The period before it is judged (what came late has been read by now). tx_lost, rx_dropped: the
 * bus's counts so far (the ring keeps what each period added). */
void lateness_begin(lateness_t *lt, uint32_t period, int64_t wake_ns, int64_t sync_ns, double sync_sent_s,
                    int64_t wait_ns, uint64_t tx_lost, uint64_t rx_dropped);
/* A joint's state was read at now_ns (sent_s: when its sender sent it, -1 unknown). back: 0 it is
 * the current period's, in time; 1 it came late for the current period (read before the next
 * period begins); 2 it came late for the period before the current one. */
void lateness_state(lateness_t *lt, int64_t now_ns, double sent_s, unsigned back);
/* The period's wait is over: these joints' states did not come. */
void lateness_missing(lateness_t *lt, uint32_t missing);
/* The side a period's lateness was on, and by how much (us). */
late_side_t lateness_judge(const late_period_t *p, int32_t *by_us);
const char *lateness_side_name(late_side_t side);
/* What made `periods` periods (the most recent ones, less the `skip` latest) miss their states, on one line: the
 * side most of them were late on, by how much, and the controller's own wake-ups beside it. Judges
 * the current period with what has come so far (tx_lost, rx_dropped: the bus's counts now).
 * Returns the side. */
late_side_t lateness_explain(lateness_t *lt, uint32_t skip, uint32_t periods, uint64_t tx_lost, uint64_t rx_dropped,
                             char *out, size_t cap);
/* The most recent `k`-th period (0: the current one), or NULL. */
const late_period_t *lateness_at(const lateness_t *lt, uint32_t k);

#endif
