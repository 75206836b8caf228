/* The LCM URLs this project accepts: telemetry stays on this host.
 *
 * Accepted: "" (no telemetry) or udpm://GROUP:PORT[?KEY=VALUE&...] with GROUP an IPv4 multicast
 * address, PORT 1..65535, and the parameters ttl (required, exactly "0" wherever it appears) and
 * recv_buf_size (a positive integer). Anything else is refused with a message naming the URL and
 * the part that is wrong: a substring test for "ttl=0" would pass "ttl=0x5", "ttl=01" or
 * "ttl=0&ttl=3", which LCM reads as TTL 5, 1 and 3. */
#ifndef ARM_LCM_URL_H
#define ARM_LCM_URL_H

#include <stddef.h>
#include <stdint.h>

typedef struct {
    int none;          /* the empty URL: no telemetry */
    uint32_t group_be; /* network byte order */
    uint16_t port;
} arm_lcm_url_t;

/* 0, or -1 with a message naming `option` and the URL in err. */
int arm_lcm_url_parse(const char *url, const char *option, arm_lcm_url_t *out, char *err, size_t errcap);

/* 0 if the kernel routes the group to the loopback interface (the longest matching route of
 * /proc/net/route is on lo), else -1 with the command that fixes it in err. */
int arm_lcm_url_check_route(const arm_lcm_url_t *u, const char *option, char *err, size_t errcap);

/* A UDP socket that receives the group's datagrams on this host alone: bound to the group (never
 * INADDR_ANY: datagrams unicast to the port from elsewhere do not arrive), its membership on lo,
 * shared with other listeners (SO_REUSEADDR/SO_REUSEPORT); rcvbuf > 0 sizes its queue; nonblock: reads
 * never wait. The descriptor, or -1 with a message naming `option` and the URL in err. */
int arm_lcm_url_open_rx(const arm_lcm_url_t *u, const char *option, const char *url, int rcvbuf, int nonblock,
                        char *err, size_t errcap);

#endif
