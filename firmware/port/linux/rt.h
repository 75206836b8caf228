/* Real-time set-up of the controller's loop thread (Linux): SCHED_FIFO when permitted,
 * mlockall(MCL_CURRENT | MCL_FUTURE), a prefaulted stack, optional CPU affinity.
 * The loop itself (controller_loop.c) sleeps with clock_nanosleep(TIMER_ABSTIME) on an absolute
 * schedule and counts overruns; this file only prepares the thread it runs on. */
#ifndef ARM_RT_H
#define ARM_RT_H

#include <stddef.h>
#include <stdint.h>

#define RT_PRIORITY_AUTO (-1) /* realtime mode: the registry's rt-priority constant; lockstep: no SCHED_FIFO */
#define RT_STACK_PREFAULT_BYTES (256u * 1024u)

typedef struct {
    int cpu;         /* --cpu N: pin the loop thread to CPU N; -1 = no affinity */
    int rt_priority; /* --rt-priority P: 1..99 SCHED_FIFO, 0 = stay SCHED_OTHER, or AUTO */
    /* --debug-slow-step-us N: TEST HOOK ONLY. Busy-waits N us inside every control step (counted
     * as compute time) so tests can force overruns. Not in --help; never use it on hardware. */
    uint32_t debug_slow_step_us;
} rt_options_t;

typedef struct {
    int sched_fifo;    /* 1: the loop thread runs SCHED_FIFO at priority */
    int priority;
    int memory_locked; /* 1: mlockall(MCL_CURRENT | MCL_FUTURE) succeeded */
    int cpu;           /* the CPU the thread is pinned to, or -1 */
    size_t stack_prefaulted;
    char message[400]; /* one line: what was applied, and every fallback with its reason */
} rt_status_t;

void rt_options_default(rt_options_t *o);
/* Parses one option's value; 0, or -1 with a message naming the option and value in err. */
int rt_option_parse(const char *name, const char *value, rt_options_t *o, char *err,
                    unsigned long errcap);

/* Applies the options to the calling thread (call it from the loop's thread, after other threads
 * were started: they keep the ordinary policy). realtime: 1 for the wall-clock mode (an AUTO
 * priority becomes SCHED_FIFO, memory is locked), 0 for lockstep (only what was asked for).
 * Returns 0, or -1 (message in st->message) if an explicitly requested CPU cannot be used.
 * A refused SCHED_FIFO or mlockall is not an error: the loop runs without it and says so. */
int rt_setup(const rt_options_t *o, int realtime, rt_status_t *st);

/* The test hook's busy wait (CLOCK_MONOTONIC). */
void rt_debug_busy_wait_us(uint32_t us);

#endif
