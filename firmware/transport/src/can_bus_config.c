/* --bus parsing and the bus set's configuration (arm/can_bus_config.h): portable, no OS calls. */
#include "arm/can_bus_config.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/can_mem.h"
#include "arm/can_udp.h"

#define SOCKETCAN_PREFIX "socketcan:"
#define MEM_PREFIX "mem:"
#define SLCAN_PREFIX "slcan:"
#define UART_PREFIX "uart:"

int arm_can_bus_ifname_valid(const char *ifname)
{
    if (ifname == NULL) {
        return -1;
    }
    const size_t n = strlen(ifname);
    if (n == 0u || n > ARM_CAN_BUS_IFNAME_MAX || strcmp(ifname, ".") == 0 ||
        strcmp(ifname, "..") == 0) {
        return -1;
    }
    for (size_t i = 0; i < n; ++i) {
        const unsigned char c = (unsigned char)ifname[i];
        if (c == '/' || c == ':' || c <= ' ' || c == 0x7fu) {
            return -1;
        }
    }
    return 0;
}

/* "HOST:PORT": an IPv4 literal (digits and dots: no name lookup) and a port 1..65535. */
static int parse_host_port(const char *s, char *host, size_t cap, uint16_t *port)
{
    const char *colon = strrchr(s, ':');
    if (colon == NULL || colon == s || (size_t)(colon - s) >= cap) {
        return -1;
    }
    for (const char *c = s; c < colon; ++c) {
        if ((*c < '0' || *c > '9') && *c != '.') return -1;
    }
    memcpy(host, s, (size_t)(colon - s));
    host[colon - s] = '\0';
    char *end = NULL;
    const long p = strtol(colon + 1, &end, 10);
    if (end == colon + 1 || *end != '\0' || p < 1 || p > 65535) {
        return -1;
    }
    *port = (uint16_t)p;
    return 0;
}

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
        if (arm_can_bus_ifname_valid(ifname) != 0) {
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
    } else if (strncmp(spec, SLCAN_PREFIX, strlen(SLCAN_PREFIX)) == 0) {
        if (parse_host_port(spec + strlen(SLCAN_PREFIX), s.host, sizeof(s.host), &s.port) != 0) {
            snprintf(err, errcap, "--bus: '%s': expected slcan:HOST:PORT, HOST an IPv4 address (e.g. slcan:127.0.0.1:46004)",
                     spec);
            return -1;
        }
        s.kind = ARM_BUS_SLCAN;
    } else if (strncmp(spec, UART_PREFIX, strlen(UART_PREFIX)) == 0) {
        const char *k = spec + strlen(UART_PREFIX);
        char *end = NULL;
        const long uart = strtol(k, &end, 10);
        if (end == k || *end != '\0' || uart < 0 || uart >= (long)ARM_CAN_BUS_UARTS) {
            snprintf(err, errcap, "--bus: '%s': the MCU's SLCAN UARTs are uart:0 .. uart:%u", spec, ARM_CAN_BUS_UARTS - 1u);
            return -1;
        }
        s.kind = ARM_BUS_UART;
        s.line = (unsigned)uart;
    } else if (parse_udp(spec, s.group, sizeof(s.group), &s.port) == 0) {
        s.kind = ARM_BUS_UDP;
    } else {
        snprintf(err, errcap,
                 "--bus: unknown bus '%s' (expected udp, udp:GROUP:PORT, socketcan:IFACE, mem:K, slcan:HOST:PORT or uart:N)",
                 spec);
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
    if (a->kind == ARM_BUS_MEM || a->kind == ARM_BUS_UART) return a->line == b->line;
    if (a->kind == ARM_BUS_SLCAN) return a->port == b->port && strcmp(a->host, b->host) == 0;
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

