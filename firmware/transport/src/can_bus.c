#define _GNU_SOURCE
#include "arm/can_bus.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

int arm_can_bus_spec_valid(const char *spec, char *err, size_t errcap)
{
    char group[64];
    uint16_t port = 0;
    if (parse_udp(spec, group, sizeof(group), &port) == 0) {
        return 0;
    }
    snprintf(err, errcap, "--bus: unknown bus '%s' (expected udp or udp:GROUP:PORT)", spec);
    return -1;
}

int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap)
{
    char group[64];
    uint16_t port = 0;
    memset(bus, 0, sizeof(*bus));
    if (arm_can_bus_spec_valid(spec, err, errcap) != 0) {
        return -1;
    }
    (void)parse_udp(spec, group, sizeof(group), &port);
    bus->kind = ARM_BUS_UDP;
    return arm_can_udp_open(&bus->udp, group, port, err, errcap);
}

int arm_can_bus_send(arm_can_bus_t *bus, const arm_can_frame_t *f)
{
    return arm_can_udp_send(&bus->udp, f, arm_can_udp_now());
}

int arm_can_bus_recv(arm_can_bus_t *bus, arm_can_frame_t *f, int timeout_us)
{
    double ts = 0.0;
    return arm_can_udp_recv(&bus->udp, f, &ts, timeout_us);
}

void arm_can_bus_close(arm_can_bus_t *bus)
{
    arm_can_udp_close(&bus->udp);
}
