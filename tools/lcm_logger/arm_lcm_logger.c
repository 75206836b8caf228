/* arm_lcm_logger: records every LCM message of a HIL run to an LCM log file (lcm-logplayer and
 * lcm-spy read it), without losing messages when it falls behind for a moment.
 *
 * Why not lcm-logger: it subscribes with LCM's default queue of 30 messages per subscription.
 * LCM's receive thread reads the socket as fast as it can and drops a message when a subscriber
 * already has 30 waiting, so any 10 ms stall of the logger's main thread (a 2-core machine, disk
 * writeback) loses telemetry although the kernel socket buffer has room for seconds of it
 * (measured: a 50 ms SIGSTOP lost 206 of 13,500 messages). Here the queue is unbounded and the
 * socket buffer comes from the URL (recv_buf_size), so a stall only delays writing.
 *
 * Usage: arm_lcm_logger --lcm-url URL FILE. Flushes the file about every 100 ms while messages come;
 * SIGINT/SIGTERM: writes what is queued, closes the file, prints the count and exits 0 (1 if a
 * write failed). */
#define _POSIX_C_SOURCE 200809L
#include <lcm/lcm.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define FLUSH_INTERVAL_NS 100000000LL

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
} logger_t;

static void flush_log(logger_t *lg)
{
    (void)fflush(lg->log->f);
    lg->last_flush_ns = mono_ns();
}

static void on_message(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    logger_t *lg = (logger_t *)user;
    lcm_eventlog_event_t ev;
    memset(&ev, 0, sizeof ev);
    ev.timestamp = rbuf->recv_utime;
    ev.channellen = (int32_t)strlen(channel);
    ev.datalen = (int32_t)rbuf->data_size;
    ev.channel = (char *)channel;
    ev.data = rbuf->data;
    if (lcm_eventlog_write_event(lg->log, &ev) != 0) {
        lg->write_errors++;
        return;
    }
    lg->written++;
    if (mono_ns() - lg->last_flush_ns >= FLUSH_INTERVAL_NS) {
        flush_log(lg);
    }
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
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    (void)sigaction(SIGINT, &sa, NULL);
    (void)sigaction(SIGTERM, &sa, NULL);

    logger_t lg;
    memset(&lg, 0, sizeof lg);
    lg.log = lcm_eventlog_create(path, "w");
    if (lg.log == NULL) {
        perror("arm_lcm_logger: cannot create the log file");
        return 1;
    }
    lcm_t *lcm = lcm_create(url);
    if (lcm == NULL) {
        fprintf(stderr, "arm_lcm_logger: cannot open LCM URL '%s'\n", url);
        lcm_eventlog_destroy(lg.log);
        return 1;
    }
    lcm_subscription_t *sub = lcm_subscribe(lcm, ".*", on_message, &lg);
    if (sub == NULL || lcm_subscription_set_queue_capacity(sub, 0) != 0) { /* 0: no limit */
        fprintf(stderr, "arm_lcm_logger: cannot subscribe\n");
        lcm_destroy(lcm);
        lcm_eventlog_destroy(lg.log);
        return 1;
    }
    while (!g_stop) {
        if (lcm_handle_timeout(lcm, 50) < 0) {
            break;
        }
        if (lg.written > 0 && mono_ns() - lg.last_flush_ns >= FLUSH_INTERVAL_NS) {
            flush_log(&lg);
        }
    }
    /* Write what LCM has queued already: everything that arrived before the signal. */
    while (lcm_handle_timeout(lcm, 20) > 0) {
    }
    lcm_unsubscribe(lcm, sub);
    lcm_destroy(lcm);
    flush_log(&lg);
    lcm_eventlog_destroy(lg.log);
    fprintf(stderr, "arm_lcm_logger: %llu messages written, %llu write errors\n", (unsigned long long)lg.written,
            (unsigned long long)lg.write_errors);
    return lg.write_errors == 0 ? 0 : 1;
}
