/* The control step's cost on the target: SysTick ticks per call, turned into instructions. */
#ifndef ARM_CORTEX_M_STEP_COUNT_H
#define ARM_CORTEX_M_STEP_COUNT_H

/* Prints, for the PM step (float), the arm's RNEA kernel and the general arm_rnea: SysTick ticks
 * per call and instructions per call. SysTick runs on the core clock: on silicon a tick is a
 * cycle. Under QEMU with -icount shift=0 a tick is a fixed number of instructions (QEMU counts
 * instructions, it does not model cycles), measured by a loop of known length. Returns 0. */
int report_step_cost(void);

#endif
