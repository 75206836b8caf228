#define _DEFAULT_SOURCE
#include "arm/lcm_url.h"

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

static int fail(char *err, size_t errcap, const char *option, const char *url, const char *why)
{
    snprintf(err, errcap, "%s: '%s': %s", option, url, why);
    return -1;
}

static int parse_uint(const char *s, size_t len, unsigned long lo, unsigned long hi, unsigned long *out)
{
    if (len == 0u || len > 10u) {
        return -1;
    }
    unsigned long v = 0;
    for (size_t i = 0; i < len; ++i) {
        if (s[i] < '0' || s[i] > '9') {
            return -1;
        }
        v = v * 10u + (unsigned long)(s[i] - '0');
    }
    if (v < lo || v > hi) {
        return -1;
    }
    *out = v;
    return 0;
}

int arm_lcm_url_parse(const char *url, const char *option, arm_lcm_url_t *out, char *err, size_t errcap)
{
    memset(out, 0, sizeof(*out));
    if (url[0] == '\0') {
        out->none = 1;
        return 0;
    }
    static const char scheme[] = "udpm://";
    if (strncmp(url, scheme, sizeof(scheme) - 1u) != 0) {
        return fail(err, errcap, option, url, "expected udpm://GROUP:PORT?ttl=0 (or '' for none)");
    }
    const char *host = url + sizeof(scheme) - 1u;
    const char *colon = strchr(host, ':');
    const char *query = strchr(host, '?');
    if (colon == NULL || (query != NULL && query < colon)) {
        return fail(err, errcap, option, url, "expected udpm://GROUP:PORT?ttl=0 (no port)");
    }
    char group[32];
    const size_t glen = (size_t)(colon - host);
    if (glen == 0u || glen >= sizeof(group)) {
        return fail(err, errcap, option, url, "the group is not an IPv4 multicast address");
    }
    memcpy(group, host, glen);
    group[glen] = '\0';
    struct in_addr addr;
    if (inet_pton(AF_INET, group, &addr) != 1 || (ntohl(addr.s_addr) >> 28) != 0xEu) {
        return fail(err, errcap, option, url, "the group is not an IPv4 multicast address (224.0.0.0/4)");
    }
    const char *port_s = colon + 1;
    const size_t plen = query != NULL ? (size_t)(query - port_s) : strlen(port_s);
    unsigned long port = 0;
    if (parse_uint(port_s, plen, 1u, 65535u, &port) != 0) {
        return fail(err, errcap, option, url, "the port is not a number in 1..65535");
    }
    int ttl_seen = 0;
    const char *p = query != NULL ? query + 1 : NULL;
    while (p != NULL && *p != '\0') {
        const char *amp = strchr(p, '&');
        const size_t len = amp != NULL ? (size_t)(amp - p) : strlen(p);
        const char *eq = memchr(p, '=', len);
        if (eq == NULL) {
            return fail(err, errcap, option, url, "a parameter without '=' (expected KEY=VALUE)");
        }
        const size_t klen = (size_t)(eq - p);
        const char *v = eq + 1;
        const size_t vlen = len - klen - 1u;
        unsigned long n = 0;
        if (klen == 3u && memcmp(p, "ttl", 3u) == 0) {
            if (vlen != 1u || v[0] != '0') {
                return fail(err, errcap, option, url, "ttl must be exactly 0 (telemetry stays on this host)");
            }
            ttl_seen = 1;
        } else if (klen == 13u && memcmp(p, "recv_buf_size", 13u) == 0) {
            if (parse_uint(v, vlen, 1u, 1UL << 30, &n) != 0) {
                return fail(err, errcap, option, url, "recv_buf_size must be a number of bytes in 1..2^30");
            }
        } else {
            return fail(err, errcap, option, url, "unknown parameter (known: ttl, recv_buf_size)");
        }
        p = amp != NULL ? amp + 1 : NULL;
    }
    if (!ttl_seen) {
        return fail(err, errcap, option, url, "must set ttl=0 (telemetry stays on this host)");
    }
    out->group_be = addr.s_addr;
    out->port = (uint16_t)port;
    return 0;
}

int arm_lcm_url_check_route(const arm_lcm_url_t *u, const char *option, char *err, size_t errcap)
{
    if (u->none) {
        return 0;
    }
    char group[INET_ADDRSTRLEN] = "?";
    const struct in_addr ga = {.s_addr = u->group_be};
    inet_ntop(AF_INET, &ga, group, sizeof(group));
    /* The kernel's IPv4 routes (main table), longest prefix first: /proc/net/route prints each
     * destination and mask as the raw network-order word, so they compare with group_be as is. */
    FILE *f = fopen("/proc/net/route", "r");
    if (f == NULL) {
        snprintf(err, errcap, "%s: cannot read /proc/net/route to check the route of %s: %s", option, group,
                 strerror(errno));
        return -1;
    }
    char line[256], best_if[32] = "";
    int best_len = -1;
    while (fgets(line, sizeof line, f) != NULL) {
        char ifname[32];
        unsigned dest = 0, gw = 0, flags = 0, mask = 0;
        int refcnt, use, metric;
        if (sscanf(line, "%31s %x %x %x %d %d %d %x", ifname, &dest, &gw, &flags, &refcnt, &use, &metric,
                   &mask) != 8 || (flags & 0x1u) == 0u) { /* RTF_UP */
            continue;
        }
        const int len = __builtin_popcount(mask);
        if ((u->group_be & mask) == dest && len > best_len) {
            best_len = len;
            snprintf(best_if, sizeof best_if, "%s", ifname);
        }
    }
    fclose(f);
    if (strcmp(best_if, "lo") != 0) {
        snprintf(err, errcap, "%s: multicast group %s is routed %s%s, not to lo: memberships and IGMP reports "
                 "would leave this host; run as root: ip route replace %s/32 dev lo", option, group,
                 best_len < 0 ? "nowhere" : "via ", best_if, group);
        return -1;
    }
    return 0;
}

int arm_lcm_url_open_rx(const arm_lcm_url_t *u, const char *option, const char *url, int rcvbuf, int nonblock,
                        char *err, size_t errcap)
{
    const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC | (nonblock ? SOCK_NONBLOCK : 0), 0);
    if (fd < 0) {
        snprintf(err, errcap, "%s: '%s': socket: %s", option, url, strerror(errno));
        return -1;
    }
    const int one = 1;
    (void)setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    (void)setsockopt(fd, SOL_SOCKET, SO_REUSEPORT, &one, sizeof one);
    if (rcvbuf > 0) {
        (void)setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    }
#ifdef IP_MULTICAST_ALL
    const int zero = 0;
    (void)setsockopt(fd, IPPROTO_IP, IP_MULTICAST_ALL, &zero, sizeof zero);
#endif
    struct sockaddr_in addr = {.sin_family = AF_INET, .sin_port = htons(u->port)};
    addr.sin_addr.s_addr = u->group_be;
    struct ip_mreq mreq;
    mreq.imr_multiaddr.s_addr = u->group_be;
    mreq.imr_interface.s_addr = htonl(INADDR_LOOPBACK); /* the membership (and IGMP) stays on lo */
    if (bind(fd, (const struct sockaddr *)&addr, sizeof addr) != 0 ||
        setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof mreq) != 0) {
        snprintf(err, errcap, "%s: '%s': cannot join the group on lo: %s", option, url, strerror(errno));
        close(fd);
        return -1;
    }
    return fd;
}
