/* The in-process bus of software-in-the-loop runs (spec "mem:K", K = 0..ARM_CAN_MEM_LINES-1): the
 * controller and the emulated drives in one process and one thread hand frames across in memory.
 * Every frame gets one sequence number across all lines, so a bus set receives in exactly the order
 * frames were sent, on whichever bus (a wire keeps the order on one bus; sockets lose it between
 * buses, which is why the simulator reorders UDP and SocketCAN input and never needs to here).
 * A full queue drops the frame, as a full transmit queue does (the sender counts it).
 *
 * Both ends open the same spec; arm_can_mem_set_opening_side says which end the next opens are.
 * The master end has an idle hook: a receive that finds nothing queued gives the drives their turn
 * (the SIL runner's simulator step) before it answers, and it never waits. */
#ifndef ARM_CAN_MEM_H
#define ARM_CAN_MEM_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"

#define ARM_CAN_MEM_LINES 4u
#define ARM_CAN_MEM_QUEUE 1024u /* frames per line and direction: hundreds of periods of traffic */
#define ARM_CAN_MEM_EMPTY UINT64_MAX

typedef enum { ARM_CAN_MEM_MASTER = 0, ARM_CAN_MEM_DRIVES = 1 } arm_can_mem_side_t;

typedef struct {
    unsigned line;
    arm_can_mem_side_t side;
    int open;
} arm_can_mem_t;

void arm_can_mem_set_opening_side(arm_can_mem_side_t side);
/* hook(ctx) runs when a master-end receive finds nothing queued; NULL: none. */
void arm_can_mem_set_idle_hook(void (*hook)(void *ctx), void *ctx);
/* Empties every line (a new run). */
void arm_can_mem_reset(void);

int arm_can_mem_open(arm_can_mem_t *bus, unsigned line, char *err, size_t errcap);
/* 0, or -2 (ARM_BUS_E_WOULD_BLOCK) when the peer's queue is full: dropped. */
int arm_can_mem_send(arm_can_mem_t *bus, const arm_can_frame_t *f);
/* 1 with the oldest frame queued for this end, 0 when none (never waits; no idle hook). */
int arm_can_mem_recv(arm_can_mem_t *bus, arm_can_frame_t *f);
/* The sequence number of the oldest frame queued for this end, or ARM_CAN_MEM_EMPTY. */
uint64_t arm_can_mem_head(const arm_can_mem_t *bus);
/* Runs the idle hook if this is a master end with one (a receive found nothing). */
void arm_can_mem_idle(const arm_can_mem_t *bus);
void arm_can_mem_close(arm_can_mem_t *bus);

#endif
