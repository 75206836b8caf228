/* arm_lcm_logger: records every LCM message of a HIL run to an LCM log file (lcm-logplayer and
 * lcm-spy read it) without losing messages, and without taking the CPU the run needs.
 *
 * Why not lcm-logger, nor liblcm's receive path: lcm-logger subscribes with LCM's default queue
 * of 30 messages, and LCM's receive thread drops a message when a subscriber already has 30
 * waiting, so a 10 ms stall of its main thread loses telemetry (measured: a 50 ms SIGSTOP lost
 * 206 of 13,500 messages). And liblcm hands each message from its receive thread to the main
 * thread through a queue and a notification pipe: several syscalls and two wake-ups per message,
 * about a third of a lockstep run's CPU on a 2-core machine. Here one thread reads the UDP
 * multicast socket itself (LCM's UDPM wire format, "LC02" packets), up to 64 datagrams per
 * recvmmsg, and sleeps between batches: the kernel socket buffer (recv_buf_size in the URL) is the
 * queue, seconds deep at HIL rates. Timestamps are the kernel's receive times (SO_TIMESTAMP), as
 * lcm-logger's. The file is written with liblcm's own event-log writer.
 *
 * Fragmented LCM messages ("LC03", over about 64 KB) are not reassembled: the project's
 * telemetry types are a few hundred bytes. They are counted and named on exit, never silently
 * dropped.
 *
 * Usage: arm_lcm_logger --lcm-url URL FILE. The URL must keep telemetry on this host (TTL 0, the
 * group routed to lo: arm/lcm_url.h). Prints "arm_lcm_logger: ready" on stdout once it receives;
 * flushes about every 100 ms while messages come; SIGINT/SIGTERM/SIGHUP: writes what the socket
 * holds (and what arrives in the next 20 ms), closes the file, prints the counts on stderr and
 * exits 0 (1 if a write failed or a message could not be logged; 2 on a bad URL). */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <lcm/eventlog.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <time.h>
#include <unistd.h>

#include "arm/lcm_url.h"

#define FLUSH_INTERVAL_NS 100000000LL
#define BATCH 64
#define DGRAM_MAX 65536   /* the largest UDP datagram: LC02 packets are at most that */
#define IDLE_SLEEP_NS 2000000L /* between batches: wake-ups cost the run CPU; the socket queues */
#define MAGIC_SHORT 0x4c433032u /* "LC02": a whole message in one datagram */
#define MAGIC_LONG 0x4c433033u  /* "LC03": one fragment of a larger message */

static volatile sig_atomic_t g_stop = 0;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static int64_t mono_ns(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + (int64_t)ts.tv_nsec;
}

typedef struct {
    lcm_eventlog_t *log;
    int64_t last_flush_ns;
    uint64_t written;
    uint64_t write_errors;
    uint64_t fragmented;  /* LC03 fragments: not logged (see the header comment) */
    uint64_t malformed;   /* neither LC02 nor LC03, or a channel without its terminator */
} logger_t;

static uint32_t be32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

static void log_datagram(logger_t *lg, const uint8_t *buf, size_t n, int64_t utime)
{
    if (n >= 4u && be32(buf) == MAGIC_LONG) {
        lg->fragmented++;
        return;
    }
    if (n < 8u || be32(buf) != MAGIC_SHORT) {
        lg->malformed++;
        return;
    }
    const uint8_t *chan = buf + 8;
    const uint8_t *nul = memchr(chan, '\0', n - 8u);
    if (nul == NULL) {
        lg->malformed++;
        return;
    }
    lcm_eventlog_event_t ev;
    memset(&ev, 0, sizeof ev);
    ev.timestamp = utime;
    ev.channellen = (int32_t)(nul - chan);
    ev.channel = (char *)chan;
    ev.data = (void *)(nul + 1);
    ev.datalen = (int32_t)(n - (size_t)(nul + 1 - buf));
    if (lcm_eventlog_write_event(lg->log, &ev) != 0) {
        lg->write_errors++;
        return;
    }
    lg->written++;
}

static int open_socket(const arm_lcm_url_t *u, const char *url, int rcvbuf)
{
    char err[300];
    const int fd = arm_lcm_url_open_rx(u, "--lcm-url", url, rcvbuf, 0, err, sizeof err);
    if (fd < 0) {
        fprintf(stderr, "arm_lcm_logger: %s\n", err);
        return -1;
    }
    const int one = 1;
    (void)setsockopt(fd, SOL_SOCKET, SO_TIMESTAMP, &one, sizeof one);
    return fd;
}

/* recv_buf_size=N of the URL (arm_lcm_url_parse has checked it), or 0. */
static int url_rcvbuf(const char *url)
{
    const char *p = strstr(url, "recv_buf_size=");
    return p != NULL ? atoi(p + strlen("recv_buf_size=")) : 0;
}

typedef struct {
    struct mmsghdr msgs[BATCH];
    struct iovec iov[BATCH];
    uint8_t ctrl[BATCH][CMSG_SPACE(sizeof(struct timeval))];
    uint8_t buf[BATCH][DGRAM_MAX];
} batch_t;

/* Reads what is queued (up to a batch; flags MSG_DONTWAIT or MSG_WAITFORONE) and logs it: the
 * count, 0 when nothing was queued, -1 on an error other than EINTR/EAGAIN. */
static int drain_batch(logger_t *lg, int fd, batch_t *b, int flags)
{
    for (int i = 0; i < BATCH; ++i) {
        b->iov[i].iov_base = b->buf[i];
        b->iov[i].iov_len = sizeof b->buf[i];
        memset(&b->msgs[i], 0, sizeof b->msgs[i]);
        b->msgs[i].msg_hdr.msg_iov = &b->iov[i];
        b->msgs[i].msg_hdr.msg_iovlen = 1;
        b->msgs[i].msg_hdr.msg_control = b->ctrl[i];
        b->msgs[i].msg_hdr.msg_controllen = sizeof b->ctrl[i];
    }
    const int got = recvmmsg(fd, b->msgs, BATCH, flags, NULL);
    if (got < 0) {
        return (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK) ? 0 : -1;
    }
    for (int i = 0; i < got; ++i) {
        int64_t utime = 0;
        for (struct cmsghdr *c = CMSG_FIRSTHDR(&b->msgs[i].msg_hdr); c != NULL;
             c = CMSG_NXTHDR(&b->msgs[i].msg_hdr, c)) {
            if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMP) {
                struct timeval tv;
                memcpy(&tv, CMSG_DATA(c), sizeof tv);
                utime = (int64_t)tv.tv_sec * 1000000 + tv.tv_usec;
            }
        }
        if (utime == 0) {
            struct timeval tv;
            gettimeofday(&tv, NULL);
            utime = (int64_t)tv.tv_sec * 1000000 + tv.tv_usec;
        }
        log_datagram(lg, b->buf[i], b->msgs[i].msg_len, utime);
    }
    return got;
}

int main(int argc, char **argv)
{
    const char *url = NULL;
    const char *path = NULL;
    for (int i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--lcm-url") == 0 && i + 1 < argc) {
            url = argv[++i];
        } else if (argv[i][0] != '-' && path == NULL) {
            path = argv[i];
        } else {
            fprintf(stderr, "arm_lcm_logger: unexpected argument '%s'\nusage: %s --lcm-url URL FILE\n", argv[i],
                    argv[0]);
            return 2;
        }
    }
    if (url == NULL || path == NULL) {
        fprintf(stderr, "usage: %s --lcm-url URL FILE\n", argv[0]);
        return 2;
    }
    char err[600];
    arm_lcm_url_t u;
    if (arm_lcm_url_parse(url, "--lcm-url", &u, err, sizeof err) != 0 || u.none ||
        arm_lcm_url_check_route(&u, "--lcm-url", err, sizeof err) != 0) {
        fprintf(stderr, "arm_lcm_logger: %s\n", u.none ? "--lcm-url: '' logs nothing: give a udpm:// URL" : err);
        return 2;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    (void)sigaction(SIGINT, &sa, NULL);
    (void)sigaction(SIGTERM, &sa, NULL);
    (void)sigaction(SIGHUP, &sa, NULL);

    const int fd = open_socket(&u, url, url_rcvbuf(url));
    if (fd < 0) {
        return 1;
    }
    logger_t lg;
    memset(&lg, 0, sizeof lg);
    lg.log = lcm_eventlog_create(path, "w");
    if (lg.log == NULL) {
        perror("arm_lcm_logger: cannot create the log file");
        close(fd);
        return 1;
    }
    /* Ready: the membership is in place and the file open, so nothing published from now on is
     * missed (tools/run/hil.py starts the run when it reads this line). */
    printf("arm_lcm_logger: ready\n");
    (void)fflush(stdout);
    static batch_t batch; /* 4 MB: static, not on the stack */
    int failed = 0;
    while (!g_stop) {
        struct pollfd pfd = {.fd = fd, .events = POLLIN};
        const int pr = poll(&pfd, 1, 50);
        if (pr < 0 && errno != EINTR) {
            failed = 1;
            break;
        }
        int got = 0;
        while (pr > 0 && !g_stop && (got = drain_batch(&lg, fd, &batch, MSG_DONTWAIT)) == BATCH) {
        }
        if (got < 0) {
            failed = 1;
            break;
        }
        if (lg.written > 0 && mono_ns() - lg.last_flush_ns >= FLUSH_INTERVAL_NS) {
            (void)fflush(lg.log->f);
            lg.last_flush_ns = mono_ns();
        }
        if (pr > 0) { /* let a batch build up: one wake-up per batch, not per message */
            const struct timespec idle = {.tv_sec = 0, .tv_nsec = IDLE_SLEEP_NS};
            (void)nanosleep(&idle, NULL);
        }
    }
    /* What the socket holds arrived before the signal: write it all, and what still comes in
     * the next 20 ms (a publisher that has just exited may have datagrams in flight). */
    for (;;) {
        while (drain_batch(&lg, fd, &batch, MSG_DONTWAIT) > 0) {
        }
        struct pollfd pfd = {.fd = fd, .events = POLLIN};
        if (poll(&pfd, 1, 20) <= 0) {
            break;
        }
    }
    close(fd);
    (void)fflush(lg.log->f);
    lcm_eventlog_destroy(lg.log);
    fprintf(stderr, "arm_lcm_logger: %llu messages written, %llu write errors, %llu fragmented not logged, "
            "%llu malformed\n", (unsigned long long)lg.written, (unsigned long long)lg.write_errors,
            (unsigned long long)lg.fragmented, (unsigned long long)lg.malformed);
    return !failed && lg.write_errors == 0 && lg.fragmented == 0 ? 0 : 1;
}
