/* What the controller loop (controller_loop.c) asks of the port it runs on: a clock, a sleep to a
 * deadline, and the control step, timed. Linux: CLOCK_MONOTONIC and clock_nanosleep (rt.c). The
 * MCU image (firmware/port/cortex_m/mcu_clock.c): SysTick, WFI, and the step's instructions
 * counted in the loop (processor in the loop). */
#ifndef ARM_LOOP_PORT_H
#define ARM_LOOP_PORT_H

#include <stdint.h>

#include "arm/controller.h"

/* Monotonic time, ns. */
int64_t port_clock_ns(void);
/* Returns once port_clock_ns() >= t_ns (at once if it is already). */
void port_clock_sleep_until(int64_t t_ns);
/* 1 where lockstep periods, too, begin on the clock's period (the MCU's SysTick-driven SYNC):
 * a period's states are still waited for, but the next SYNC goes no sooner than its time. */
extern const int port_paces_lockstep;
/* arm_ctl_step, as the port measures it. */
void port_control_step(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out);

#endif
