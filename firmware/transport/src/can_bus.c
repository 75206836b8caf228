#define _GNU_SOURCE
#include "arm/can_bus.h"
#include "arm/fd_wait.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define SOCKETCAN_PREFIX "socketcan:"
#define MEM_PREFIX "mem:"

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
    } else if (strncmp(spec, MEM_PREFIX, strlen(MEM_PREFIX)) == 0) {
        const char *k = spec + strlen(MEM_PREFIX);
        char *end = NULL;
        const long line = strtol(k, &end, 10);
        if (end == k || *end != '\0' || line < 0 || line >= (long)ARM_CAN_MEM_LINES) {
            snprintf(err, errcap, "--bus: '%s': the in-process bus is mem:0 .. mem:%u", spec, ARM_CAN_MEM_LINES - 1u);
            return -1;
        }
        s.kind = ARM_BUS_MEM;
        s.line = (unsigned)line;
    } else if (parse_udp(spec, s.group, sizeof(s.group), &s.port) == 0) {
        s.kind = ARM_BUS_UDP;
    } else {
        snprintf(err, errcap,
                 "--bus: unknown bus '%s' (expected udp, udp:GROUP:PORT, socketcan:IFACE or mem:K)", spec);
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
    bus->udp.tx_fd = -1;
    bus->socketcan.fd = -1;
    if (arm_can_bus_parse_spec(spec, &s, err, errcap) != 0) {
        return -1;
    }
    bus->kind = s.kind;
    if (s.kind == ARM_BUS_MEM) {
        return arm_can_mem_open(&bus->mem, s.line, err, errcap);
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
    if (bus->kind == ARM_BUS_MEM) {
        if (timeout_us != 0 && arm_can_mem_head(&bus->mem) == ARM_CAN_MEM_EMPTY) {
            arm_can_mem_idle(&bus->mem);
        }
        return arm_can_mem_recv(&bus->mem, f);
    }
    if (bus->kind == ARM_BUS_SOCKETCAN) {
        return arm_can_socketcan_recv(&bus->socketcan, f, timeout_us);
    }
    double ts = 0.0;
    return arm_can_udp_recv(&bus->udp, f, &ts, timeout_us);
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
    arm_can_udp_close(&bus->udp);
}

uint64_t arm_can_bus_rx_undecodable(const arm_can_bus_t *bus)
{
    switch (bus->kind) {
    case ARM_BUS_UDP: return bus->udp.rx_decode_errors;
    case ARM_BUS_SOCKETCAN: return bus->socketcan.rx_decode_errors;
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

void arm_can_bus_set_config_init(arm_can_bus_set_config_t *cfg)
{
    memset(cfg, 0, sizeof(*cfg));
}

/* "1-3", "4,5,6", "1-2,6" -> mask of drives 1..n_drives; -1 if malformed or out of range. */
static int parse_drives(const char *s, unsigned n_drives, uint32_t *mask)
{
    uint32_t m = 0u;
    const char *p = s;
    for (;;) {
        char *end = NULL;
        if (*p < '0' || *p > '9') return -1;
        const long lo = strtol(p, &end, 10);
        long hi = lo;
        p = end;
        if (*p == '-') {
            ++p;
            if (*p < '0' || *p > '9') return -1;
            hi = strtol(p, &end, 10);
            p = end;
        }
        if (lo < 1 || hi < lo || hi > (long)n_drives) return -1;
        for (long d = lo; d <= hi; ++d) m |= 1u << (unsigned)(d - 1);
        if (*p == '\0') break;
        if (*p != ',') return -1;
        ++p;
    }
    *mask = m;
    return 0;
}

static int same_spec(const arm_can_bus_spec_t *a, const arm_can_bus_spec_t *b)
{
    if (a->kind != b->kind) return 0;
    if (a->kind == ARM_BUS_SOCKETCAN) return strcmp(a->ifname, b->ifname) == 0;
    if (a->kind == ARM_BUS_MEM) return a->line == b->line;
    return a->port == b->port && strcmp(a->group, b->group) == 0;
}

static uint32_t all_drives(unsigned n_drives)
{
    return n_drives >= 32u ? 0xFFFFFFFFu : (1u << n_drives) - 1u;
}

int arm_can_bus_set_add(arm_can_bus_set_config_t *cfg, const char *arg, unsigned n_drives,
                        const char *option, char *err, size_t errcap)
{
    if (n_drives < 1u || n_drives > ARM_CAN_BUS_SET_MAX_DRIVES) {
        snprintf(err, errcap, "%s: %u drives not supported (1..%u)", option, n_drives,
                 ARM_CAN_BUS_SET_MAX_DRIVES);
        return -1;
    }
    if (cfg->n >= ARM_CAN_BUS_SET_MAX) {
        snprintf(err, errcap, "%s: '%s': at most %u buses", option, arg, ARM_CAN_BUS_SET_MAX);
        return -1;
    }
    const char *at = strrchr(arg, '@');
    const size_t spec_len = at != NULL ? (size_t)(at - arg) : strlen(arg);
    if (spec_len >= ARM_CAN_BUS_SPEC_MAX) {
        snprintf(err, errcap, "%s: '%s': bus spec longer than %u characters", option, arg,
                 ARM_CAN_BUS_SPEC_MAX - 1u);
        return -1;
    }
    const unsigned i = cfg->n;
    memcpy(cfg->spec[i], arg, spec_len);
    cfg->spec[i][spec_len] = '\0';
    char perr[200];
    if (arm_can_bus_parse_spec(cfg->spec[i], &cfg->parsed[i], perr, sizeof perr) != 0) {
        /* perr starts with "--bus: "; name the caller's option instead */
        const char *why = strncmp(perr, "--bus: ", 7) == 0 ? perr + 7 : perr;
        snprintf(err, errcap, "%s: %s", option, why);
        return -1;
    }
    uint32_t mask = all_drives(n_drives);
    if (at != NULL && parse_drives(at + 1, n_drives, &mask) != 0) {
        snprintf(err, errcap,
                 "%s: '%s': drives '%s' are not a list of drives 1..%u (e.g. @1-3 or @4,5,6)",
                 option, arg, at + 1, n_drives);
        return -1;
    }
    for (unsigned k = 0; k < i; ++k) {
        if (same_spec(&cfg->parsed[k], &cfg->parsed[i])) {
            snprintf(err, errcap, "%s: bus '%s' is given twice ('%s' and '%s')", option,
                     cfg->spec[i], cfg->spec[k], cfg->spec[i]);
            return -1;
        }
    }
    cfg->drive_mask[i] = mask;
    cfg->n = i + 1u;
    return 0;
}

static void list_drives(uint32_t mask, char *out, size_t cap)
{
    size_t len = 0;
    out[0] = '\0';
    for (unsigned d = 0; d < 32u && len + 4u < cap; ++d) {
        if ((mask & (1u << d)) != 0u) {
            len += (size_t)snprintf(out + len, cap - len, "%s%u", len > 0 ? "," : "", d + 1u);
        }
    }
}

int arm_can_bus_set_check(const arm_can_bus_set_config_t *cfg, unsigned n_drives,
                          const char *option, char *err, size_t errcap)
{
    if (cfg->n == 0u) {
        snprintf(err, errcap, "%s: no bus given", option);
        return -1;
    }
    uint32_t seen = 0u;
    for (unsigned i = 0; i < cfg->n; ++i) {
        const uint32_t twice = seen & cfg->drive_mask[i];
        if (twice != 0u) {
            const unsigned d = (unsigned)__builtin_ctz(twice);
            unsigned k = 0;
            while (k < i && (cfg->drive_mask[k] & (1u << d)) == 0u) ++k;
            snprintf(err, errcap, "%s: drive %u is on two buses ('%s' and '%s'); each drive on exactly one",
                     option, d + 1u, cfg->spec[k], cfg->spec[i]);
            return -1;
        }
        seen |= cfg->drive_mask[i];
    }
    const uint32_t missing = all_drives(n_drives) & ~seen;
    if (missing != 0u) {
        char list[100];
        list_drives(missing, list, sizeof list);
        snprintf(err, errcap, "%s: drive(s) %s on no bus (give each drive a bus: SPEC@DRIVES, e.g. %s@1-3)",
                 option, list, cfg->spec[0]);
        return -1;
    }
    return 0;
}

int arm_can_bus_set_bus_of(const arm_can_bus_set_config_t *cfg, unsigned joint)
{
    for (unsigned i = 0; i < cfg->n && joint < 32u; ++i) {
        if ((cfg->drive_mask[i] & (1u << joint)) != 0u) return (int)i;
    }
    return -1;
}

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
    return b->kind == ARM_BUS_SOCKETCAN ? b->socketcan.fd : b->udp.fd;
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
