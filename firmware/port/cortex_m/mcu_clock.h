/* The MCU image's clock (SysTick at 1 kHz on the boards' 25 MHz clock) and what it measures of the
 * control step in the loop (firmware/port/linux/loop_port.h is the interface). */
#ifndef ARM_MCU_CLOCK_H
#define ARM_MCU_CLOCK_H

#include <stdint.h>

void mcu_clock_start(void);
/* SysTick's count of time since mcu_clock_start, ns. */
int64_t systick_ns(void);
/* Instructions of the last port_control_step, counted in SysTick ticks of a known number of
 * instructions (QEMU -icount shift=0: one instruction per virtual ns, a tick 40 of them; the
 * measurement starts and ends on a tick's edge, so it is exact to the few instructions of one
 * poll of the counter). 0 before the first step. */
uint32_t mcu_last_step_instructions(void);
/* Instructions per tick, calibrated at start by a loop of known length (step_count.c's way). */
uint32_t mcu_instructions_per_tick(void);
void SysTick_Handler(void);

#endif
