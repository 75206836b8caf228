/* rt.h on the MCU: the image runs no operating system, so the Linux loop's scheduling options
 * (--rt-priority, --cpu) and its test hook are refused with a line that says why. */
#include <stdio.h>

#include "rt.h"

void rt_options_default(rt_options_t *o)
{
    o->cpu = -1;
    o->rt_priority = RT_PRIORITY_AUTO;
    o->debug_slow_step_us = 0u;
}

int rt_option_parse(const char *name, const char *value, rt_options_t *o, char *err, unsigned long errcap)
{
    (void)o;
    snprintf(err, errcap, "%s %s: the MCU image has no operating system to schedule its loop (SysTick paces it)",
             name, value);
    return -1;
}

void rt_debug_busy_wait_us(uint32_t us)
{
    (void)us; /* never set: rt_option_parse refuses the hook */
}
