#define _GNU_SOURCE
#include "lcm_sink.h"

#include <lcm/eventlog.h>
#include <lcm/lcm.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define LOG_BUFFER (1u << 20)

struct lcm_sink {
    lcm_t *lcm;           /* a HIL run */
    lcm_eventlog_t *log;  /* a software-in-the-loop run */
    int64_t events;
    int write_failed;
};

lcm_sink_t *lcm_sink_open_url(const char *url, char *err, size_t errcap)
{
    lcm_sink_t *s = calloc(1, sizeof(*s)); /* start-up only */
    if (s == NULL) {
        snprintf(err, errcap, "telemetry: out of memory");
        return NULL;
    }
    s->lcm = lcm_create(url);
    if (s->lcm == NULL) {
        snprintf(err, errcap, "--lcm-url: LCM could not open '%s'", url);
        free(s);
        return NULL;
    }
    return s;
}

lcm_sink_t *lcm_sink_open_log(const char *path, char *err, size_t errcap)
{
    lcm_sink_t *s = calloc(1, sizeof(*s));
    if (s == NULL) {
        snprintf(err, errcap, "telemetry: out of memory");
        return NULL;
    }
    s->log = lcm_eventlog_create(path, "w");
    if (s->log == NULL) {
        snprintf(err, errcap, "--telemetry-log: cannot create '%s'", path);
        free(s);
        return NULL;
    }
    /* before any write: liblcm writes an event in five fwrites, and stdio's default 4 KiB buffer
     * made a write(2) every few periods, about a tenth of a software-in-the-loop period */
    setvbuf(s->log->f, NULL, _IOFBF, LOG_BUFFER);
    return s;
}

static int64_t wall_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

int lcm_sink_publish(lcm_sink_t *s, const char *channel, const void *data, unsigned len)
{
    if (s->log != NULL) {
        lcm_eventlog_event_t ev = {
            .eventnum = s->events++,
            .timestamp = wall_us(),
            .channellen = (int32_t)strlen(channel),
            .datalen = (int32_t)len,
            .channel = (char *)channel,
            .data = (void *)data,
        };
        if (lcm_eventlog_write_event(s->log, &ev) != 0) {
            s->write_failed = 1;
            return -1;
        }
        return 0;
    }
    return lcm_publish(s->lcm, channel, data, len) == 0 ? 0 : -1;
}

int lcm_sink_close(lcm_sink_t *s)
{
    if (s == NULL) return 0;
    int rc = 0;
    if (s->lcm != NULL) lcm_destroy(s->lcm);
    if (s->log != NULL) {
        /* lcm_eventlog_destroy closes the FILE without saying whether the last flush landed */
        rc = fflush(s->log->f) == 0 && !s->write_failed ? 0 : -1;
        lcm_eventlog_destroy(s->log);
    }
    free(s);
    return rc;
}
