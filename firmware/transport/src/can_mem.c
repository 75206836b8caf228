#include "arm/can_mem.h"

#include <stdio.h>
#include <string.h>

typedef struct {
    arm_can_frame_t f;
    uint64_t seq;
} slot_t;

typedef struct {
    slot_t q[ARM_CAN_MEM_QUEUE];
    unsigned head, len;
} queue_t;

/* to[side]: what that end receives. Static: a run's whole traffic lives here, nothing allocated. */
static queue_t lines[ARM_CAN_MEM_LINES][2];
static uint64_t next_seq;
static arm_can_mem_side_t opening_side = ARM_CAN_MEM_MASTER;
static void (*idle_hook)(void *);
static void *idle_ctx;

void arm_can_mem_set_opening_side(arm_can_mem_side_t side)
{
    opening_side = side;
}

void arm_can_mem_set_idle_hook(void (*hook)(void *ctx), void *ctx)
{
    idle_hook = hook;
    idle_ctx = ctx;
}

void arm_can_mem_reset(void)
{
    memset(lines, 0, sizeof(lines));
    next_seq = 0u;
}

int arm_can_mem_open(arm_can_mem_t *bus, unsigned line, char *err, size_t errcap)
{
    if (line >= ARM_CAN_MEM_LINES) {
        snprintf(err, errcap, "--bus: 'mem:%u': the in-process bus has lines 0..%u", line, ARM_CAN_MEM_LINES - 1u);
        return -1;
    }
    bus->line = line;
    bus->side = opening_side;
    bus->open = 1;
    return 0;
}

int arm_can_mem_send(arm_can_mem_t *bus, const arm_can_frame_t *f)
{
    queue_t *to = &lines[bus->line][bus->side == ARM_CAN_MEM_MASTER ? ARM_CAN_MEM_DRIVES : ARM_CAN_MEM_MASTER];
    if (!bus->open || to->len == ARM_CAN_MEM_QUEUE) {
        return -2;
    }
    slot_t *s = &to->q[(to->head + to->len) % ARM_CAN_MEM_QUEUE];
    s->f = *f;
    s->seq = next_seq++;
    to->len++;
    return 0;
}

int arm_can_mem_recv(arm_can_mem_t *bus, arm_can_frame_t *f)
{
    queue_t *q = &lines[bus->line][bus->side];
    if (!bus->open || q->len == 0u) {
        return 0;
    }
    *f = q->q[q->head].f;
    q->head = (q->head + 1u) % ARM_CAN_MEM_QUEUE;
    q->len--;
    return 1;
}

uint64_t arm_can_mem_head(const arm_can_mem_t *bus)
{
    const queue_t *q = &lines[bus->line][bus->side];
    return bus->open && q->len > 0u ? q->q[q->head].seq : ARM_CAN_MEM_EMPTY;
}

void arm_can_mem_idle(const arm_can_mem_t *bus)
{
    if (bus->side == ARM_CAN_MEM_MASTER && idle_hook != NULL) {
        idle_hook(idle_ctx);
    }
}

void arm_can_mem_close(arm_can_mem_t *bus)
{
    bus->open = 0;
}
