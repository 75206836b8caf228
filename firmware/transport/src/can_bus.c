#define _GNU_SOURCE
#include "arm/can_bus.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SOCKETCAN_PREFIX "socketcan:"

static int parse_udp(const char *spec, char *group, size_t cap, uint16_t *port)
{
    snprintf(group, cap, "%s", ARM_CAN_UDP_DEFAULT_GROUP);
    *port = (uint16_t)ARM_CAN_UDP_DEFAULT_PORT;
    if (strcmp(spec, "udp") == 0) {
        return 0;
    }
    if (strncmp(spec, "udp:", 4) != 0) {
        return -1;
    }
    const char *g = spec + 4;
    const char *colon = strrchr(g, ':');
    if (colon == NULL || colon == g || (size_t)(colon - g) >= cap) {
        return -1;
    }
    memcpy(group, g, (size_t)(colon - g));
    group[colon - g] = '\0';
    char *end = NULL;
    const long p = strtol(colon + 1, &end, 10);
    if (end == colon + 1 || *end != '\0' || p < 1 || p > 65535) {
        return -1;
    }
    *port = (uint16_t)p;
    return 0;
}

int arm_can_bus_parse_spec(const char *spec, arm_can_bus_spec_t *out, char *err, size_t errcap)
{
    arm_can_bus_spec_t s;
    memset(&s, 0, sizeof s);
    if (spec == NULL) {
        snprintf(err, errcap, "--bus: missing bus spec");
        return -1;
    }
    if (strncmp(spec, SOCKETCAN_PREFIX, strlen(SOCKETCAN_PREFIX)) == 0) {
        const char *ifname = spec + strlen(SOCKETCAN_PREFIX);
        if (arm_can_socketcan_ifname_valid(ifname) != 0) {
            snprintf(err, errcap,
                     "--bus: '%s': interface name must be 1..15 characters without '/', ':' or "
                     "spaces (e.g. socketcan:vcan0)", spec);
            return -1;
        }
        s.kind = ARM_BUS_SOCKETCAN;
        snprintf(s.ifname, sizeof s.ifname, "%s", ifname);
    } else if (parse_udp(spec, s.group, sizeof(s.group), &s.port) == 0) {
        s.kind = ARM_BUS_UDP;
    } else {
        snprintf(err, errcap,
                 "--bus: unknown bus '%s' (expected udp, udp:GROUP:PORT or socketcan:IFACE)", spec);
        return -1;
    }
    if (out != NULL) {
        *out = s;
    }
    return 0;
}

int arm_can_bus_spec_valid(const char *spec, char *err, size_t errcap)
{
    return arm_can_bus_parse_spec(spec, NULL, err, errcap);
}

int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap)
{
    arm_can_bus_spec_t s;
    memset(bus, 0, sizeof(*bus));
    bus->udp.fd = -1;
    bus->socketcan.fd = -1;
    if (arm_can_bus_parse_spec(spec, &s, err, errcap) != 0) {
        return -1;
    }
    bus->kind = s.kind;
    if (s.kind == ARM_BUS_SOCKETCAN) {
        if (arm_can_socketcan_open(&bus->socketcan, s.ifname, err, errcap) != 0) {
            return -1;
        }
        /* The drives answer in CAN FD frames (DRIVE_i_STATE, 16 bytes): a classic-only
         * interface would look like drives that never answer. Say so at open instead. */
        if (bus->socketcan.mtu >= 0 && bus->socketcan.mtu < (int)CANFD_MTU) {
            snprintf(err, errcap,
                     "socketcan:%s: MTU %d carries classic CAN only; the drive protocol needs "
                     "CAN FD (MTU 72: ip link set %s mtu 72)",
                     s.ifname, bus->socketcan.mtu, s.ifname);
            arm_can_socketcan_close(&bus->socketcan);
            return -1;
        }
        return 0;
    }
    return arm_can_udp_open(&bus->udp, s.group, s.port, err, errcap);
}

int arm_can_bus_send(arm_can_bus_t *bus, const arm_can_frame_t *f)
{
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        return arm_can_socketcan_send(&bus->socketcan, f);
    }
    return arm_can_udp_send(&bus->udp, f, arm_can_udp_now());
}

int arm_can_bus_recv(arm_can_bus_t *bus, arm_can_frame_t *f, int timeout_us)
{
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        return arm_can_socketcan_recv(&bus->socketcan, f, timeout_us);
    }
    double ts = 0.0;
    return arm_can_udp_recv(&bus->udp, f, &ts, timeout_us);
}

void arm_can_bus_close(arm_can_bus_t *bus)
{
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        arm_can_socketcan_close(&bus->socketcan);
        return;
    }
    arm_can_udp_close(&bus->udp);
}
