#define _GNU_SOURCE
#include "arm/can_bus.h"
#include "arm/fd_wait.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap)
{
    arm_can_bus_spec_t s;
    memset(bus, 0, sizeof(*bus));
    bus->udp.fd = -1;
    bus->udp.tx_fd = -1;
    bus->socketcan.fd = -1;
    if (arm_can_bus_parse_spec(spec, &s, err, errcap) != 0) {
        return -1;
    }
    bus->slcan.fd = -1;
    bus->kind = s.kind;
    if (s.kind == ARM_BUS_MEM) {
        return arm_can_mem_open(&bus->mem, s.line, err, errcap);
    }
    if (s.kind == ARM_BUS_SLCAN) {
        return arm_can_slcan_open(&bus->slcan, s.host, s.port, err, errcap);
    }
    if (s.kind == ARM_BUS_UART) {
        snprintf(err, errcap, "--bus: '%s' is a UART of the MCU image (tools/armctl hil --target); here: "
                 "slcan:HOST:PORT reaches an SLCAN link", spec);
        return -1;
    }
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
    if (bus->kind == ARM_BUS_MEM) {
        return arm_can_mem_send(&bus->mem, f);
    }
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        return arm_can_socketcan_send(&bus->socketcan, f);
    }
    if (bus->kind == ARM_BUS_SLCAN) {
        return arm_can_slcan_send(&bus->slcan, f);
    }
    return arm_can_udp_send(&bus->udp, f, arm_can_udp_now());
}

unsigned arm_can_bus_send_many(arm_can_bus_t *bus, const arm_can_frame_t *frames, unsigned n)
{
    if (bus->kind == ARM_BUS_UDP) {
        return arm_can_udp_send_many(&bus->udp, frames, n, arm_can_udp_now());
    }
    unsigned sent = 0;
    for (unsigned i = 0; i < n; ++i) {
        sent += arm_can_bus_send(bus, &frames[i]) == 0 ? 1u : 0u;
    }
    return sent;
}

int arm_can_bus_recv(arm_can_bus_t *bus, arm_can_frame_t *f, int timeout_us)
{
    bus->rx_sent_s = -1.0;
    if (bus->kind == ARM_BUS_MEM) {
        if (timeout_us != 0 && arm_can_mem_head(&bus->mem) == ARM_CAN_MEM_EMPTY) {
            arm_can_mem_idle(&bus->mem);
        }
        return arm_can_mem_recv(&bus->mem, f);
    }
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        return arm_can_socketcan_recv(&bus->socketcan, f, timeout_us);
    }
    if (bus->kind == ARM_BUS_SLCAN) {
        return arm_can_slcan_recv(&bus->slcan, f, timeout_us);
    }
    double ts = -1.0;
    const int rc = arm_can_udp_recv(&bus->udp, f, &ts, timeout_us);
    if (rc == 1) bus->rx_sent_s = ts;
    return rc;
}

double arm_can_bus_set_sent_s(const arm_can_bus_set_t *set, unsigned index)
{
    /* only UDP frames carry it (the in-process bus's set reads past arm_can_bus_recv) */
    return index < set->n && set->bus[index].kind == ARM_BUS_UDP ? set->bus[index].rx_sent_s : -1.0;
}

double arm_can_bus_clock_s(void)
{
    return arm_can_udp_now();
}

void arm_can_bus_close(arm_can_bus_t *bus)
{
    if (bus->kind == ARM_BUS_MEM) {
        arm_can_mem_close(&bus->mem);
        return;
    }
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        arm_can_socketcan_close(&bus->socketcan);
        return;
    }
    if (bus->kind == ARM_BUS_SLCAN) {
        arm_can_slcan_close(&bus->slcan);
        return;
    }
    arm_can_udp_close(&bus->udp);
}

uint64_t arm_can_bus_rx_undecodable(const arm_can_bus_t *bus)
{
    switch (bus->kind) {
    case ARM_BUS_UDP: return bus->udp.rx_decode_errors;
    case ARM_BUS_SOCKETCAN: return bus->socketcan.rx_decode_errors;
    case ARM_BUS_SLCAN: return arm_slcan_rx_refused(&bus->slcan.dec);
    default: return 0u;
    }
}

uint64_t arm_can_bus_rx_kernel_drops(const arm_can_bus_t *bus)
{
    switch (bus->kind) {
    case ARM_BUS_UDP: return bus->udp.rx_kernel_drops;
    case ARM_BUS_SOCKETCAN: return bus->socketcan.rx_kernel_drops;
    default: return 0u;
    }
}

/* ---- bus set ---------------------------------------------------------------------------------- */

int arm_can_bus_set_open(arm_can_bus_set_t *set, const arm_can_bus_set_config_t *cfg, char *err,
                         size_t errcap)
{
    memset(set, 0, sizeof(*set));
    unsigned mem = 0;
    for (unsigned i = 0; i < cfg->n && i < ARM_CAN_BUS_SET_MAX; ++i) mem += cfg->parsed[i].kind == ARM_BUS_MEM;
    if (mem != 0u && mem != cfg->n) {
        snprintf(err, errcap, "--bus: in-process buses (mem:K) cannot be mixed with other buses in one set");
        return -1;
    }
    for (unsigned i = 0; i < cfg->n && i < ARM_CAN_BUS_SET_MAX; ++i) {
        if (arm_can_bus_open(&set->bus[i], cfg->spec[i], err, errcap) != 0) {
            arm_can_bus_set_close(set);
            return -1;
        }
        set->n = i + 1u;
    }
    return 0;
}

int arm_can_bus_set_send(arm_can_bus_set_t *set, unsigned index, const arm_can_frame_t *f)
{
    if (index >= set->n) return ARM_BUS_E_INVALID;
    return arm_can_bus_send(&set->bus[index], f);
}

unsigned arm_can_bus_set_send_many(arm_can_bus_set_t *set, unsigned index, const arm_can_frame_t *frames,
                                   unsigned n)
{
    if (index >= set->n) return 0u;
    return arm_can_bus_send_many(&set->bus[index], frames, n);
}

/* In-process buses: the oldest frame sent on any of them (one order across the set). */
static int mem_set_recv(arm_can_bus_set_t *set, arm_can_frame_t *f, unsigned *index, int timeout_us)
{
    for (int pass = 0; pass < 2; ++pass) {
        uint64_t oldest = ARM_CAN_MEM_EMPTY;
        unsigned at = 0u;
        for (unsigned i = 0; i < set->n; ++i) {
            const uint64_t h = arm_can_mem_head(&set->bus[i].mem);
            if (h < oldest) {
                oldest = h;
                at = i;
            }
        }
        if (oldest != ARM_CAN_MEM_EMPTY) {
            *index = at;
            return arm_can_mem_recv(&set->bus[at].mem, f);
        }
        if (pass == 0 && timeout_us != 0) {
            arm_can_mem_idle(&set->bus[0].mem); /* the peer's turn; then whatever it sent */
        } else {
            break;
        }
    }
    return 0;
}

static int bus_fd(const arm_can_bus_t *b)
{
    switch (b->kind) {
    case ARM_BUS_SOCKETCAN: return b->socketcan.fd;
    case ARM_BUS_SLCAN: return b->slcan.fd;
    default: return b->udp.fd;
    }
}

int arm_can_bus_set_recv(arm_can_bus_set_t *set, arm_can_frame_t *f, unsigned *index, int timeout_us)
{
    if (set->n == 0u) return ARM_BUS_E_CLOSED;
    if (set->bus[0].kind == ARM_BUS_MEM) return mem_set_recv(set, f, index, timeout_us);
    if (set->n == 1u) { /* one bus: exactly the single-bus behaviour */
        *index = 0u;
        return arm_can_bus_recv(&set->bus[0], f, timeout_us);
    }
    const int64_t deadline = arm_deadline_ns(timeout_us);
    for (;;) {
        /* Drain: whatever is queued on any bus, starting after the last bus served. */
        for (unsigned k = 0; k < set->n; ++k) {
            const unsigned i = (set->next + k) % set->n;
            const int rc = arm_can_bus_recv(&set->bus[i], f, 0);
            if (rc != 0) {
                *index = i;
                set->next = (i + 1u) % set->n;
                return rc;
            }
        }
        struct pollfd pfd[ARM_CAN_BUS_SET_MAX];
        for (unsigned i = 0; i < set->n; ++i) {
            pfd[i].fd = bus_fd(&set->bus[i]);
            pfd[i].events = POLLIN;
            pfd[i].revents = 0;
        }
        struct timespec ts;
        const struct timespec *tsp = NULL;
        if (deadline >= 0) {
            const int64_t left = deadline - arm_mono_ns();
            if (left <= 0) return 0;
            ts.tv_sec = (time_t)(left / 1000000000);
            ts.tv_nsec = (long)(left % 1000000000);
            tsp = &ts;
        }
        const int pr = ppoll(pfd, (nfds_t)set->n, tsp, NULL);
        if (pr < 0 && errno != EINTR) {
            *index = 0u;
            return ARM_BUS_E_IO;
        }
        if (pr == 0) return 0;
        for (unsigned i = 0; i < set->n; ++i) {
            if ((pfd[i].revents & (POLLERR | POLLHUP | POLLNVAL)) != 0 && (pfd[i].revents & POLLIN) == 0) {
                *index = i; /* e.g. the interface went away: not a busy loop */
                return ARM_BUS_E_IO;
            }
        }
        /* something is ready (or EINTR): drain again */
    }
}

void arm_can_bus_set_close(arm_can_bus_set_t *set)
{
    for (unsigned i = 0; i < set->n; ++i) arm_can_bus_close(&set->bus[i]);
    set->n = 0u;
}
