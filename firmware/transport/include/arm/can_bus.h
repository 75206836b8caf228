/* The controller's CAN buses, whatever carries them: one interface for the controller loop
 * (firmware/port/linux/controller_loop.c), with two implementations: Linux (src/can_bus.c: UDP
 * multicast, SocketCAN, the in-process bus, SLCAN over TCP) and the MCU image
 * (firmware/port/cortex_m/can_uart_bus.c: SLCAN on the board's UARTs, built with
 * ARM_PORT_MCU 1). The --bus specs and the bus set's configuration: arm/can_bus_config.h. */
#ifndef ARM_CAN_BUS_H
#define ARM_CAN_BUS_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_bus_config.h"
#include "arm/can_frame.h"

#if ARM_PORT_MCU
#include "can_uart_bus.h" /* the MCU port's arm_can_bus_t and arm_can_bus_set_t */
#else
#include "arm/can_mem.h"
#include "arm/can_slcan.h"
#include "arm/can_socketcan.h"
#include "arm/can_udp.h"

typedef struct {
    arm_bus_kind_t kind;
    arm_can_udp_t udp;             /* kind == ARM_BUS_UDP */
    arm_can_socketcan_t socketcan; /* kind == ARM_BUS_SOCKETCAN */
    arm_can_mem_t mem;             /* kind == ARM_BUS_MEM */
    arm_can_slcan_t slcan;         /* kind == ARM_BUS_SLCAN */
    double rx_sent_s;              /* the last frame received: when its sender sent it (arm_can_bus_sent_s) */
} arm_can_bus_t;

typedef struct {
    unsigned n;
    arm_can_bus_t bus[ARM_CAN_BUS_SET_MAX];
    unsigned next; /* round-robin start of the next drain, so no bus starves another */
} arm_can_bus_set_t;
#endif

/* Parses spec and opens the bus; on failure returns -1 with a message naming the spec. */
int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap);
int arm_can_bus_send(arm_can_bus_t *bus, const arm_can_frame_t *f);
/* n frames in order, in one syscall where the transport allows (UDP: sendmmsg, up to
 * ARM_CAN_UDP_TX_BATCH); returns how many were sent, the rest dropped and counted. */
unsigned arm_can_bus_send_many(arm_can_bus_t *bus, const arm_can_frame_t *frames, unsigned n);
int arm_can_bus_recv(arm_can_bus_t *bus, arm_can_frame_t *f, int timeout_us);
void arm_can_bus_close(arm_can_bus_t *bus);
/* The transport's own counts: frames it could not decode, frames the kernel dropped on a full
 * receive queue (an in-process bus has neither). */
uint64_t arm_can_bus_rx_undecodable(const arm_can_bus_t *bus);
uint64_t arm_can_bus_rx_kernel_drops(const arm_can_bus_t *bus);

/* Opens every bus of cfg; on failure closes the ones opened and returns -1 (err names the spec).
 * In-process buses (mem:K) are all or none of a set: they keep one order across the set. */
int arm_can_bus_set_open(arm_can_bus_set_t *set, const arm_can_bus_set_config_t *cfg, char *err,
                         size_t errcap);
int arm_can_bus_set_send(arm_can_bus_set_t *set, unsigned index, const arm_can_frame_t *f);
unsigned arm_can_bus_set_send_many(arm_can_bus_set_t *set, unsigned index, const arm_can_frame_t *frames,
                                   unsigned n);
/* A frame from whichever bus has one (1, *index = that bus), 0 on timeout, <0 on error (*index =
 * the failing bus). Queued frames are drained first; waits in one ppoll over every bus.
 * timeout_us < 0: no limit. In-process buses never wait: the oldest frame sent on any of them, or
 * 0 after the idle hook had its turn (arm/can_mem.h). */
int arm_can_bus_set_recv(arm_can_bus_set_t *set, arm_can_frame_t *f, unsigned *index, int timeout_us);
void arm_can_bus_set_close(arm_can_bus_set_t *set);

/* When the sender of the last frame received on bus `index` sent it, on arm_can_bus_clock_s()'s
 * clock (s), or -1 where the transport does not say (SocketCAN, SLCAN, the in-process bus): the UDP
 * transport's frames carry their sender's time (python-can's wire format). A receiver on the same
 * host tells from it a sender that was late from its own late reading. */
double arm_can_bus_set_sent_s(const arm_can_bus_set_t *set, unsigned index);
/* The clock of those times, now (s); -1 where there is none. */
double arm_can_bus_clock_s(void);

#endif
