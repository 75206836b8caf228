/* Bus timing emulation: when each frame of a period would end on a real CAN bus.
 *
 * vcan and the UDP transport deliver a frame the moment it is sent, so without this the arm sees
 * every command at the start of its period, however loaded the bus. Each bus keeps a timeline
 * (seconds from the start of the current control period): a frame occupies the bus for its
 * worst-case length (given per frame id by the caller: tools/busload.py computes exact bit
 * counts, worst-case stuffing and the FD bit-rate switch), frames ready together go in id order
 * (arbitration: lowest id first), and a bus still busy at the end of a period carries the backlog
 * into the next one, so the next SYNC waits for it.
 *
 * Frames are queued in batches in the order the protocol produces them (SYNC; the drives' states
 * once SYNC has ended; the commands once every state is in; heartbeats and EMCY at the end of the
 * period). A later batch never pre-empts an earlier one: with this protocol's ids (SYNC 0x080 <
 * EMCY 0x081.. < STATE 0x181.. < CMD 0x201.. < heartbeat 0x701..) that is what arbitration would
 * do as well, except that a heartbeat left over from the previous period goes before the next
 * SYNC instead of after it (it only ever delays that SYNC by its own length). */
#ifndef ARM_SIM_BUS_TIMING_H
#define ARM_SIM_BUS_TIMING_H

#include <stdint.h>

#define SIM_CAN_IDS 2048u /* 11-bit identifiers */
#define SIM_BATCH_MAX 32u

typedef struct {
    uint64_t periods;
    double sync_to_last_cmd_max_s;
    double sync_to_last_cmd_sum_s;
    double backlog_max_s; /* bus still busy this long after a period's end */
    uint64_t commands_late; /* ended after their period: too late for it, not applied */
} sim_bus_stats_t;

typedef struct {
    double frame_s[SIM_CAN_IDS]; /* worst-case seconds on this bus; 0: not given */
    double free;                 /* when the bus is next idle, from the period's start */
    char label[96];              /* its physical layer, for the summary */
    sim_bus_stats_t stats;
} sim_timeline_t;

void sim_timeline_init(sim_timeline_t *tl);
void sim_timeline_new_period(sim_timeline_t *tl, double period_s);
/* Frames all ready at `ready`: ends[i] is when ids[i] ends, lowest id first on the bus. */
void sim_timeline_transmit(sim_timeline_t *tl, double ready, const uint32_t *ids, unsigned n, double *ends);
/* "ID:US,ID:US,..." (ids decimal or 0x hex) into frame_s; -1 on a malformed list. */
int sim_timeline_parse_frames(sim_timeline_t *tl, const char *text);

#endif
