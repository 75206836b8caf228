/*
 * Live checks of the loopback multicast bus.
 *
 *   can_udp_selftest loopback [--port P]                 in-process self-test (ctest)
 *   can_udp_selftest --print-sockopts [--group G] [--port P]
 *   can_udp_selftest send --id ID --count N [--fd] [--ext] [--interval-us U] [--group G] [--port P]
 *   can_udp_selftest recv --id ID --count N [--timeout-ms T] [--group G] [--port P]
 *
 * send/recv frame k carries len = k % 9 (classic) or FD_LENS[k % 16] (--fd),
 * data[i] = (7k + i) & 0xFF; tests/python/test_pycan_wire.py uses the same rule.
 * recv prints "ready" once the socket is joined, then one frame_text line per
 * frame with the requested id.
 */
#define _GNU_SOURCE /* nanosleep, inet_ntop under -std=c11 */

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>

#include "arm/can_udp.h"
#include "arm/pycan_wire.h"
#include "check.h"
#include "frame_text.h"

#define DEFAULT_TEST_PORT 43197u

static const uint8_t FD_LENS[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};

typedef struct {
    const char *mode;
    const char *group;
    uint16_t port;
    uint32_t id;
    unsigned long count;
    int fd;
    int ext;
    long interval_us;
    long timeout_ms;
} opts_t;

static void sleep_us(long us)
{
    struct timespec ts = {us / 1000000L, (us % 1000000L) * 1000L};
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
    }
}

static arm_can_frame_t pattern_frame(const opts_t *o, unsigned long k)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = o->id;
    f.len = o->fd ? FD_LENS[k % 16u] : (uint8_t)(k % 9u);
    f.flags = (uint8_t)((o->fd ? (ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS) : 0u) |
                        (o->ext ? ARM_CAN_FLAG_EXT : 0u));
    for (unsigned i = 0; i < f.len; ++i) {
        f.data[i] = (uint8_t)(7u * k + i);
    }
    return f;
}

static int open_or_report(arm_can_udp_t *bus, const opts_t *o)
{
    char err[256];
    if (arm_can_udp_open(bus, o->group, o->port, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return -1;
    }
    return 0;
}

static int print_sockopts(const opts_t *o)
{
    arm_can_udp_t bus;
    if (open_or_report(&bus, o) != 0) {
        return 1;
    }
    int ttl = -1, loop = -1, all = -1;
    struct in_addr ifaddr;
    memset(&ifaddr, 0, sizeof ifaddr);
    socklen_t len = sizeof ttl;
    int rc = getsockopt(bus.fd, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, &len);
    len = sizeof ifaddr;
    rc |= getsockopt(bus.fd, IPPROTO_IP, IP_MULTICAST_IF, &ifaddr, &len);
    len = sizeof loop;
    rc |= getsockopt(bus.fd, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, &len);
#ifdef IP_MULTICAST_ALL
    len = sizeof all;
    rc |= getsockopt(bus.fd, IPPROTO_IP, IP_MULTICAST_ALL, &all, &len);
#endif
    struct sockaddr_in bound;
    memset(&bound, 0, sizeof bound);
    len = sizeof bound;
    rc |= getsockname(bus.fd, (struct sockaddr *)&bound, &len);
    char ifs[INET_ADDRSTRLEN] = "?", bs[INET_ADDRSTRLEN] = "?";
    inet_ntop(AF_INET, &ifaddr, ifs, sizeof ifs);
    inet_ntop(AF_INET, &bound.sin_addr, bs, sizeof bs);
    /* the sending socket: the same confinement, its own port on 127.0.0.1 */
    int tx_ttl = -1, tx_loop = -1;
    struct in_addr tx_if;
    struct sockaddr_in tx_bound;
    memset(&tx_if, 0, sizeof tx_if);
    memset(&tx_bound, 0, sizeof tx_bound);
    len = sizeof tx_ttl;
    rc |= getsockopt(bus.tx_fd, IPPROTO_IP, IP_MULTICAST_TTL, &tx_ttl, &len);
    len = sizeof tx_if;
    rc |= getsockopt(bus.tx_fd, IPPROTO_IP, IP_MULTICAST_IF, &tx_if, &len);
    len = sizeof tx_loop;
    rc |= getsockopt(bus.tx_fd, IPPROTO_IP, IP_MULTICAST_LOOP, &tx_loop, &len);
    len = sizeof tx_bound;
    rc |= getsockname(bus.tx_fd, (struct sockaddr *)&tx_bound, &len);
    char txifs[INET_ADDRSTRLEN] = "?", txbs[INET_ADDRSTRLEN] = "?";
    inet_ntop(AF_INET, &tx_if, txifs, sizeof txifs);
    inet_ntop(AF_INET, &tx_bound.sin_addr, txbs, sizeof txbs);
    printf("ttl=%d if=%s loop=%d multicast_all=%d rcvbuf=%d bound=%s:%u tx_ttl=%d tx_if=%s tx_loop=%d "
           "tx_bound=%s:%u\n", ttl, ifs, loop, all, bus.rcvbuf_bytes, bs, (unsigned)ntohs(bound.sin_port),
           tx_ttl, txifs, tx_loop, txbs, (unsigned)ntohs(tx_bound.sin_port));
    arm_can_udp_close(&bus);
    return rc == 0 ? 0 : 1;
}

static int do_send(const opts_t *o)
{
    arm_can_udp_t bus;
    if (open_or_report(&bus, o) != 0) {
        return 1;
    }
    unsigned long sent = 0;
    for (unsigned long k = 0; k < o->count; ++k) {
        const arm_can_frame_t f = pattern_frame(o, k);
        int rc = ARM_CAN_UDP_E_WOULD_BLOCK;
        for (int attempt = 0; attempt < 1000 && rc == ARM_CAN_UDP_E_WOULD_BLOCK; ++attempt) {
            rc = arm_can_udp_send(&bus, &f, arm_can_udp_now());
            if (rc == ARM_CAN_UDP_E_WOULD_BLOCK) {
                sleep_us(1000);
            }
        }
        if (rc != ARM_CAN_UDP_OK) {
            fprintf(stderr, "send %lu failed: rc=%d errno=%s\n", k, rc, strerror(errno));
            break;
        }
        sent++;
        if (o->interval_us > 0) {
            sleep_us(o->interval_us);
        }
    }
    printf("sent=%lu tx_frames=%llu tx_would_block=%llu tx_errors=%llu\n", sent,
           (unsigned long long)bus.tx_frames, (unsigned long long)bus.tx_would_block,
           (unsigned long long)bus.tx_errors);
    arm_can_udp_close(&bus);
    return sent == o->count ? 0 : 1;
}

static int do_recv(const opts_t *o)
{
    arm_can_udp_t bus;
    if (open_or_report(&bus, o) != 0) {
        return 1;
    }
    printf("ready\n");
    fflush(stdout);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    unsigned long got = 0;
    while (got < o->count) {
        clock_gettime(CLOCK_MONOTONIC, &t1);
        const long elapsed_ms =
            (long)(t1.tv_sec - t0.tv_sec) * 1000L + (t1.tv_nsec - t0.tv_nsec) / 1000000L;
        if (elapsed_ms >= o->timeout_ms) {
            break;
        }
        arm_can_frame_t f;
        double ts;
        const int rc = arm_can_udp_recv(&bus, &f, &ts, (int)((o->timeout_ms - elapsed_ms) * 1000L));
        if (rc < 0) {
            fprintf(stderr, "recv failed: rc=%d errno=%s\n", rc, strerror(errno));
            break;
        }
        if (rc == 1 && f.id == o->id) {
            frame_text_print(stdout, &f);
            putchar('\n');
            fflush(stdout);
            got++;
        }
    }
    printf("received=%lu rx_frames=%llu rx_decode_errors=%llu\n", got,
           (unsigned long long)bus.rx_frames, (unsigned long long)bus.rx_decode_errors);
    arm_can_udp_close(&bus);
    return got == o->count ? 0 : 1;
}

/* In-process: two buses on one port see each other's frames, never their own. */
static int do_loopback(const opts_t *o)
{
    arm_can_udp_t a, b;
    if (open_or_report(&a, o) != 0 || open_or_report(&b, o) != 0) {
        return 1;
    }
    arm_can_frame_t f, got;
    double ts = -1.0;

    /* nothing queued: timeout 0 returns at once, 20 ms waits about that long */
    CHECK_MSG(arm_can_udp_recv(&b, &got, &ts, 0) == 0, "empty recv(0) returns 0");
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    CHECK_MSG(arm_can_udp_recv(&b, &got, &ts, 20000) == 0, "empty recv(20ms) returns 0");
    clock_gettime(CLOCK_MONOTONIC, &t1);
    const double waited =
        (double)(t1.tv_sec - t0.tv_sec) + (double)(t1.tv_nsec - t0.tv_nsec) * 1e-9;
    CHECK_MSG(waited >= 0.019 && waited < 0.5, "recv(20ms) waits about 20 ms");

    /* classic, FD and extended frames arrive intact on both buses */
    static const opts_t kinds[] = {
        {.id = 0x123}, {.id = 0x7FF, .fd = 1}, {.id = 0x1ABCDEF, .ext = 1},
        {.id = 0x1FFFFFFF, .ext = 1, .fd = 1},
    };
    for (unsigned long k = 0; k < 64u; ++k) {
        f = pattern_frame(&kinds[k % 4u], k);
        const double sent_ts = arm_can_udp_now();
        CHECK_MSG(arm_can_udp_send(&a, &f, sent_ts) == ARM_CAN_UDP_OK, "send");
        memset(&got, 0xEE, sizeof got);
        const int rc = arm_can_udp_recv(&b, &got, &ts, 500000);
        CHECK_MSG(rc == 1, "recv returns the frame");
        CHECK_MSG(rc == 1 && got.id == f.id && got.len == f.len && got.flags == f.flags &&
                      memcmp(got.data, f.data, sizeof f.data) == 0,
                  "frame intact");
        CHECK_MSG(ts == sent_ts, "sender timestamp carried");
    }
    /* the sender never gets its own frames back (as on SocketCAN): the kernel filter drops them */
    CHECK_MSG(arm_can_udp_recv(&a, &got, &ts, 20000) == 0, "no echo of our own frames");
    CHECK_MSG(a.rx_frames == 0u && a.rx_decode_errors == 0u, "nothing of ours was even read");
    f = pattern_frame(&kinds[1], 3);
    CHECK_MSG(arm_can_udp_send(&b, &f, 2.0) == ARM_CAN_UDP_OK, "send the other way");
    CHECK_MSG(arm_can_udp_recv(&a, &got, &ts, 500000) == 1 && got.id == f.id, "a hears b");
    CHECK_MSG(arm_can_udp_recv(&b, &got, &ts, 20000) == 0, "b hears no echo either");

    /* garbage is counted and skipped; the next valid frame is still returned */
    const uint8_t junk[] = {0x93, 0x01, 0x02, 0x03};
    struct sockaddr_in dst;
    memset(&dst, 0, sizeof dst);
    dst.sin_family = AF_INET;
    dst.sin_port = htons(a.port);
    dst.sin_addr.s_addr = a.group_be;
    CHECK_MSG(sendto(a.fd, junk, sizeof junk, 0, (struct sockaddr *)&dst, sizeof dst) ==
                  (ssize_t)sizeof junk,
              "raw junk sent");
    f = pattern_frame(&kinds[0], 5);
    CHECK_MSG(arm_can_udp_send(&a, &f, 1.0) == ARM_CAN_UDP_OK, "send after junk");
    const uint64_t before = b.rx_decode_errors;
    CHECK_MSG(arm_can_udp_recv(&b, &got, &ts, 500000) == 1 && got.len == f.len, "skip junk");
    CHECK_MSG(b.rx_decode_errors == before + 1u, "junk counted");
    CHECK_MSG(b.last_decode_error == ARM_PYCAN_E_NOT_MAP, "junk classified");

    /* invalid frames never reach the wire */
    f = pattern_frame(&kinds[0], 0);
    f.len = 9;
    CHECK_MSG(arm_can_udp_send(&a, &f, 1.0) == ARM_CAN_UDP_E_INVALID, "invalid frame refused");
    CHECK_MSG(a.tx_invalid == 1u, "tx_invalid counted");
    CHECK_MSG(arm_can_udp_send(&a, NULL, 1.0) == ARM_CAN_UDP_E_INVALID, "NULL frame refused");

    /* open errors name the step */
    arm_can_udp_t c;
    char err[256];
    CHECK_MSG(arm_can_udp_open(&c, "10.0.0.1", o->port, err, sizeof err) == -1,
              "unicast group refused");
    CHECK_MSG(strstr(err, "multicast") != NULL && c.fd == -1, "error names the step");
    printf("open error example: %s\n", err);

    arm_can_udp_close(&a);
    arm_can_udp_close(&b);
    arm_can_udp_close(&b); /* idempotent */
    CHECK_MSG(arm_can_udp_send(&a, &f, 1.0) == ARM_CAN_UDP_E_CLOSED, "send on closed bus");
    CHECK_MSG(arm_can_udp_recv(&a, &got, &ts, 0) == ARM_CAN_UDP_E_CLOSED, "recv on closed bus");
    TEST_MAIN_END();
}

static int parse_opts(int argc, char **argv, opts_t *o)
{
    memset(o, 0, sizeof *o);
    o->port = DEFAULT_TEST_PORT;
    o->timeout_ms = 5000;
    o->interval_us = 200;
    o->count = 10;
    o->id = 0x123;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--fd") == 0) {
            o->fd = 1;
        } else if (strcmp(a, "--ext") == 0) {
            o->ext = 1;
        } else if (v != NULL && strcmp(a, "--group") == 0) {
            o->group = v, i++;
        } else if (v != NULL && strcmp(a, "--port") == 0) {
            o->port = (uint16_t)strtoul(v, NULL, 0), i++;
        } else if (v != NULL && strcmp(a, "--id") == 0) {
            o->id = (uint32_t)strtoul(v, NULL, 0), i++;
        } else if (v != NULL && strcmp(a, "--count") == 0) {
            o->count = strtoul(v, NULL, 0), i++;
        } else if (v != NULL && strcmp(a, "--interval-us") == 0) {
            o->interval_us = strtol(v, NULL, 0), i++;
        } else if (v != NULL && strcmp(a, "--timeout-ms") == 0) {
            o->timeout_ms = strtol(v, NULL, 0), i++;
        } else if (a[0] != '-' && o->mode == NULL) {
            o->mode = a;
        } else if (strcmp(a, "--print-sockopts") == 0 && o->mode == NULL) {
            o->mode = "sockopts";
        } else {
            return -1;
        }
    }
    return o->mode != NULL ? 0 : -1;
}

int main(int argc, char **argv)
{
    opts_t o;
    if (parse_opts(argc, argv, &o) != 0) {
        fprintf(stderr,
                "usage: %s loopback | --print-sockopts | send | recv "
                "[--id ID --count N --fd --ext --interval-us U --timeout-ms T\n"
                "  --group G --port P]\n",
                argv[0]);
        return 64;
    }
    if (strcmp(o.mode, "sockopts") == 0) {
        return print_sockopts(&o);
    }
    if (strcmp(o.mode, "send") == 0) {
        return do_send(&o);
    }
    if (strcmp(o.mode, "recv") == 0) {
        return do_recv(&o);
    }
    if (strcmp(o.mode, "loopback") == 0) {
        return do_loopback(&o);
    }
    fprintf(stderr, "unknown mode %s\n", o.mode);
    return 64;
}
