/* The Linux port's CAN bus, whatever carries it: one interface for the controller loop.
 * Spec strings: "udp" | "udp:GROUP:PORT" (python-can udp_multicast wire format on loopback)
 *             | "socketcan:IFACE" (Linux SocketCAN, e.g. socketcan:can0 or socketcan:vcan0)
 *             | "mem:K" (the in-process bus of software-in-the-loop runs, arm/can_mem.h). */
#ifndef ARM_CAN_BUS_H
#define ARM_CAN_BUS_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"
#include "arm/can_mem.h"
#include "arm/can_socketcan.h"
#include "arm/can_udp.h"

typedef enum { ARM_BUS_UDP = 0, ARM_BUS_SOCKETCAN = 1, ARM_BUS_MEM = 2 } arm_bus_kind_t;

/* Result codes shared by every transport (recv also returns 1 for "frame received"). */
enum {
    ARM_BUS_OK = 0,
    ARM_BUS_E_IO = -1,
    ARM_BUS_E_WOULD_BLOCK = -2, /* the transmit queue is full: the frame was dropped (counted) */
    ARM_BUS_E_INVALID = -3,
    ARM_BUS_E_CLOSED = -4,
};

typedef struct {
    arm_bus_kind_t kind;
    arm_can_udp_t udp;             /* kind == ARM_BUS_UDP */
    arm_can_socketcan_t socketcan; /* kind == ARM_BUS_SOCKETCAN */
    arm_can_mem_t mem;             /* kind == ARM_BUS_MEM */
} arm_can_bus_t;

/* A parsed spec (arm_can_bus_parse_spec). */
typedef struct {
    arm_bus_kind_t kind;
    char group[64];                                /* udp: multicast group literal */
    uint16_t port;                                 /* udp: port */
    char ifname[ARM_CAN_SOCKETCAN_IFNAME_MAX + 1u]; /* socketcan: interface name */
    unsigned line;                                 /* mem: line */
} arm_can_bus_spec_t;

/* Parses spec without opening anything; 0, or -1 with a message naming the spec in err. */
int arm_can_bus_parse_spec(const char *spec, arm_can_bus_spec_t *out, char *err, size_t errcap);
/* Parses spec and opens the bus; on failure returns -1 with a message naming the spec. */
int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap);
/* Checks a spec without opening anything (for argument validation). */
int arm_can_bus_spec_valid(const char *spec, char *err, size_t errcap);
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

/* ---- bus set: several buses, drives assigned to buses -------------------------------------
 * Command-line form (controller and host_sim --bus, repeatable): SPEC[@DRIVES], DRIVES a list of
 * drive numbers and ranges (1-3, 4,5,6, 1-2,6); without @ the bus carries every drive. Each drive
 * must be on exactly one bus. No heap: everything lives in the structs. */
#define ARM_CAN_BUS_SET_MAX 4u
#define ARM_CAN_BUS_SPEC_MAX 128u
#define ARM_CAN_BUS_SET_MAX_DRIVES 32u

typedef struct {
    unsigned n;                                            /* buses given */
    char spec[ARM_CAN_BUS_SET_MAX][ARM_CAN_BUS_SPEC_MAX]; /* the SPEC part, e.g. "socketcan:can0" */
    arm_can_bus_spec_t parsed[ARM_CAN_BUS_SET_MAX];
    uint32_t drive_mask[ARM_CAN_BUS_SET_MAX];             /* bit j: drive j + 1 */
} arm_can_bus_set_config_t;

void arm_can_bus_set_config_init(arm_can_bus_set_config_t *cfg);
/* Adds one "SPEC[@DRIVES]" (drives 1..n_drives). -1 with a message naming `option` on a bad spec,
 * a bad drive list, a spec given twice or more than ARM_CAN_BUS_SET_MAX buses. */
int arm_can_bus_set_add(arm_can_bus_set_config_t *cfg, const char *arg, unsigned n_drives,
                        const char *option, char *err, size_t errcap);
/* Every drive 1..n_drives on exactly one bus; -1 with a message naming `option` otherwise. */
int arm_can_bus_set_check(const arm_can_bus_set_config_t *cfg, unsigned n_drives,
                          const char *option, char *err, size_t errcap);
/* Index of the bus that carries drive (0-based joint index), or -1. */
int arm_can_bus_set_bus_of(const arm_can_bus_set_config_t *cfg, unsigned joint);

typedef struct {
    unsigned n;
    arm_can_bus_t bus[ARM_CAN_BUS_SET_MAX];
    unsigned next; /* round-robin start of the next drain, so no bus starves another */
} arm_can_bus_set_t;

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

#endif
