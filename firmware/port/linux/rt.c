#define _GNU_SOURCE
#include "rt.h"

#include <alloca.h>
#include <errno.h>
#include <sched.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "arm_params.h"
#include "loop_port.h"

#if defined(__SANITIZE_ADDRESS__)
#define RT_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define RT_UNDER_ASAN 1
#endif
#endif
#ifndef RT_UNDER_ASAN
#define RT_UNDER_ASAN 0
#endif

void rt_options_default(rt_options_t *o)
{
    o->cpu = -1;
    o->rt_priority = RT_PRIORITY_AUTO;
    o->debug_slow_step_us = 0u;
}

static int parse_int(const char *name, const char *s, long lo, long hi, long *out, char *err,
                     unsigned long errcap)
{
    char *end = NULL;
    errno = 0;
    const long v = strtol(s, &end, 10);
    if (errno != 0 || end == s || *end != '\0' || v < lo || v > hi) {
        snprintf(err, errcap, "%s: '%s' is not a whole number in [%ld, %ld]", name, s, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

int rt_option_parse(const char *name, const char *value, rt_options_t *o, char *err,
                    unsigned long errcap)
{
    long v = 0;
    if (strcmp(name, "--cpu") == 0) {
        if (parse_int(name, value, 0, CPU_SETSIZE - 1, &v, err, errcap) != 0) return -1;
        o->cpu = (int)v;
    } else if (strcmp(name, "--rt-priority") == 0) {
        const int lo = 0, hi = sched_get_priority_max(SCHED_FIFO);
        if (parse_int(name, value, lo, hi > 0 ? hi : 99, &v, err, errcap) != 0) return -1;
        o->rt_priority = (int)v;
    } else if (strcmp(name, "--debug-slow-step-us") == 0) {
        if (parse_int(name, value, 0, 1000000, &v, err, errcap) != 0) return -1;
        o->debug_slow_step_us = (uint32_t)v;
    } else {
        snprintf(err, errcap, "unknown option '%s'", name);
        return -1;
    }
    return 0;
}

/* Touches the stack the loop will use, so its pages are mapped (and, after mlockall, locked)
 * before the first period instead of faulting in during one. */
__attribute__((noinline)) static size_t prefault_stack(size_t bytes)
{
    volatile unsigned char *buf = alloca(bytes);
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    for (size_t i = 0; i < bytes; i += page) {
        buf[i] = 0;
    }
    return bytes;
}

__attribute__((format(printf, 2, 3))) static void add(rt_status_t *st, const char *fmt, ...)
{
    size_t len = strlen(st->message);
    if (len + 3 >= sizeof(st->message)) return;
    if (len > 0) {
        st->message[len++] = ';';
        st->message[len++] = ' ';
        st->message[len] = '\0';
    }
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(st->message + len, sizeof(st->message) - len, fmt, ap);
    va_end(ap);
}

int rt_setup(const rt_options_t *o, int realtime, rt_status_t *st)
{
    memset(st, 0, sizeof(*st));
    st->cpu = -1;

    if (o->cpu >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET((size_t)o->cpu, &set);
        if (sched_setaffinity(0, sizeof(set), &set) != 0) {
            snprintf(st->message, sizeof(st->message),
                     "--cpu: cannot run on CPU %d (%s; this machine has %ld online)", o->cpu,
                     strerror(errno), sysconf(_SC_NPROCESSORS_ONLN));
            return -1;
        }
        st->cpu = o->cpu;
        add(st, "pinned to CPU %d", o->cpu);
    }

    const int prio = o->rt_priority == RT_PRIORITY_AUTO ? (realtime ? ARM_P_RT_PRIORITY : 0)
                                                        : o->rt_priority;
    if (prio > 0) {
        const struct sched_param sp = {.sched_priority = prio};
        if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0) {
            st->sched_fifo = 1;
            st->priority = prio;
            add(st, "SCHED_FIFO priority %d", prio);
        } else {
            const int e = errno;
            add(st, "SCHED_FIFO refused (%s): running SCHED_OTHER; needs root, CAP_SYS_NICE or "
                    "an rtprio limit (ulimit -r) of at least %d",
                strerror(e), prio);
        }
    } else {
        add(st, "SCHED_OTHER (rt priority 0)");
    }

    if (realtime) {
        if (RT_UNDER_ASAN) {
            /* ASan reserves terabytes of shadow address space; locking it is neither possible
             * nor meaningful. Timing figures come from the release build. */
            add(st, "memory not locked (AddressSanitizer build)");
        } else if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
            st->memory_locked = 1;
            add(st, "memory locked");
        } else {
            const int e = errno;
            add(st, "mlockall refused (%s): pages may fault in during the loop", strerror(e));
        }
        st->stack_prefaulted = prefault_stack(RT_STACK_PREFAULT_BYTES);
        add(st, "stack prefaulted %zu KiB", st->stack_prefaulted / 1024u);
    }
    return 0;
}

void rt_debug_busy_wait_us(uint32_t us)
{
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    const int64_t want = (int64_t)us * 1000;
    do {
        clock_gettime(CLOCK_MONOTONIC, &t);
    } while ((int64_t)(t.tv_sec - t0.tv_sec) * 1000000000LL + (t.tv_nsec - t0.tv_nsec) < want);
}

/* ---- loop_port.h: the Linux loop's clock ------------------------------------------------------ */

const int port_paces_lockstep = 0; /* lockstep periods follow each other as fast as the peer answers */

int64_t port_clock_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

void port_clock_sleep_until(int64_t t_ns)
{
    const struct timespec dl = {.tv_sec = t_ns / 1000000000LL, .tv_nsec = t_ns % 1000000000LL};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &dl, NULL) == EINTR) {
    }
}

void port_control_step(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out)
{
    arm_ctl_step(ctl, in, out);
}
