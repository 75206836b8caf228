/* The controller's buses as its --bus arguments name them, and what every implementation of the
 * bus interface (arm/can_bus.h) returns. Portable: no OS calls, no heap, so the Linux port and
 * the MCU image parse and check --bus alike (firmware/port/linux/options.c runs on both).
 *
 * Spec strings: "udp" | "udp:GROUP:PORT" (python-can udp_multicast wire format on loopback)
 *             | "socketcan:IFACE" (Linux SocketCAN, e.g. socketcan:can0 or socketcan:vcan0)
 *             | "mem:K" (the in-process bus of software-in-the-loop runs, arm/can_mem.h)
 *             | "slcan:HOST:PORT" (SLCAN over a TCP connection, arm/can_slcan.h: an SLCAN adapter
 *               behind a serial-to-TCP bridge, or an emulated MCU's UART)
 *             | "uart:N" (the MCU image: SLCAN on the board's UART N, firmware/port/cortex_m) */
#ifndef ARM_CAN_BUS_CONFIG_H
#define ARM_CAN_BUS_CONFIG_H

#include <stddef.h>
#include <stdint.h>

typedef enum {
    ARM_BUS_UDP = 0,
    ARM_BUS_SOCKETCAN = 1,
    ARM_BUS_MEM = 2,
    ARM_BUS_SLCAN = 3,
    ARM_BUS_UART = 4,
} arm_bus_kind_t;

/* Result codes shared by every transport (recv also returns 1 for "frame received"). */
enum {
    ARM_BUS_OK = 0,
    ARM_BUS_E_IO = -1,
    ARM_BUS_E_WOULD_BLOCK = -2, /* the transmit queue is full: the frame was dropped (counted) */
    ARM_BUS_E_INVALID = -3,
    ARM_BUS_E_CLOSED = -4,
};

#define ARM_CAN_BUS_IFNAME_MAX 15u /* longest interface name, without its NUL (IFNAMSIZ - 1) */
#define ARM_CAN_BUS_HOST_MAX 63u   /* slcan: an IPv4 address literal */
#define ARM_CAN_BUS_UARTS 4u       /* uart:0 .. uart:3 */

/* A parsed spec (arm_can_bus_parse_spec). */
typedef struct {
    arm_bus_kind_t kind;
    char group[64];                           /* udp: multicast group literal */
    uint16_t port;                            /* udp, slcan: port */
    char ifname[ARM_CAN_BUS_IFNAME_MAX + 1u]; /* socketcan: interface name */
    unsigned line;                            /* mem: line; uart: the UART */
    char host[ARM_CAN_BUS_HOST_MAX + 1u];     /* slcan: host */
} arm_can_bus_spec_t;

/* Parses spec without opening anything; 0, or -1 with a message naming the spec in err. */
int arm_can_bus_parse_spec(const char *spec, arm_can_bus_spec_t *out, char *err, size_t errcap);
/* Checks a spec without opening anything (for argument validation). */
int arm_can_bus_spec_valid(const char *spec, char *err, size_t errcap);
/* An interface name the kernel would take (1..15 bytes, not "." or "..", no '/', ':' or
 * whitespace); 0 if valid. */
int arm_can_bus_ifname_valid(const char *ifname);

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

#endif
