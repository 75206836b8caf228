/* The Linux port's CAN bus, whatever carries it: one interface for the controller loop.
 * Spec strings: "udp" | "udp:GROUP:PORT" (python-can udp_multicast wire format on loopback)
 *             | "socketcan:IFACE" (Linux SocketCAN, e.g. socketcan:can0 or socketcan:vcan0). */
#ifndef ARM_CAN_BUS_H
#define ARM_CAN_BUS_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"
#include "arm/can_socketcan.h"
#include "arm/can_udp.h"

typedef enum { ARM_BUS_UDP = 0, ARM_BUS_SOCKETCAN = 1 } arm_bus_kind_t;

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
} arm_can_bus_t;

/* A parsed spec (arm_can_bus_parse_spec). */
typedef struct {
    arm_bus_kind_t kind;
    char group[64];                                /* udp: multicast group literal */
    uint16_t port;                                 /* udp: port */
    char ifname[ARM_CAN_SOCKETCAN_IFNAME_MAX + 1u]; /* socketcan: interface name */
} arm_can_bus_spec_t;

/* Parses spec without opening anything; 0, or -1 with a message naming the spec in err. */
int arm_can_bus_parse_spec(const char *spec, arm_can_bus_spec_t *out, char *err, size_t errcap);
/* Parses spec and opens the bus; on failure returns -1 with a message naming the spec. */
int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap);
/* Checks a spec without opening anything (for argument validation). */
int arm_can_bus_spec_valid(const char *spec, char *err, size_t errcap);
int arm_can_bus_send(arm_can_bus_t *bus, const arm_can_frame_t *f);
int arm_can_bus_recv(arm_can_bus_t *bus, arm_can_frame_t *f, int timeout_us);
void arm_can_bus_close(arm_can_bus_t *bus);

#endif
