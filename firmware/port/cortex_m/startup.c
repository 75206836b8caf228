/* Reset and vector table for ARMv7-M (Cortex-M3/M4/M7) on QEMU's mps2 boards. No vendor code:
 * copy .data, clear .bss, enable the FPU if the build uses it, paint the stack (for the measured
 * high-water mark), run main, report its result through semihosting. */
#include <stdint.h>
#include <string.h>

#include "semihost.h"

extern uint32_t _sidata[], _sdata[], _edata[], _sbss[], _ebss[];
extern uint32_t _stack_limit[], _stack_top[];

int main(void);
void Reset_Handler(void);
void Fault_Handler(void);
void Default_Handler(void);
/* What an image that takes interrupts defines (the PIL image: mcu_clock.c, mcu_uart.c); the
 * golden image takes none, and one would stop it (Default_Handler). */
void SysTick_Handler(void) __attribute__((weak, alias("Default_Handler")));
void External_IRQHandler(void) __attribute__((weak, alias("Default_Handler")));

#define STACK_PAINT 0xA5A5A5A5u

__attribute__((noreturn)) void Reset_Handler(void)
{
#if defined(__ARM_FP)
    /* CPACR: full access to CP10/CP11 before the first floating-point instruction. */
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#endif
    for (uint32_t *s = _sidata, *d = _sdata; d < _edata;) {
        *d++ = *s++;
    }
    for (uint32_t *d = _sbss; d < _ebss;) {
        *d++ = 0u;
    }
    /* Paint the stack below this frame (64 bytes of headroom for it). */
    uint32_t *sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    for (uint32_t *p = _stack_limit; p < sp - 16; ++p) {
        *p = STACK_PAINT;
    }
    sh_exit(main());
}

/* Bytes of stack ever used: from the top down to the lowest word that is no longer paint. */
uint32_t stack_high_water(void)
{
    const uint32_t *p = _stack_limit;
    while (p < _stack_top && *p == STACK_PAINT) {
        ++p;
    }
    return (uint32_t)((uintptr_t)_stack_top - (uintptr_t)p);
}

void Fault_Handler(void)
{
    sh_puts("cortex-m: FAULT (hard/mem/bus/usage fault)\n");
    sh_exit(3);
}

void Default_Handler(void)
{
    sh_puts("cortex-m: unexpected interrupt\n");
    sh_exit(4);
}

typedef void (*vector_t)(void);

/* ARMv7-M: initial SP, then the exception vectors, then the mps2 FPGA images' IRQs. */
__attribute__((section(".vectors"), used)) const vector_t g_vectors[16 + 32] = {
    (vector_t)(uintptr_t)_stack_top,
    Reset_Handler,
    Default_Handler, /* NMI */
    Fault_Handler,   /* HardFault */
    Fault_Handler,   /* MemManage */
    Fault_Handler,   /* BusFault */
    Fault_Handler,   /* UsageFault */
    0, 0, 0, 0,
    Default_Handler, /* SVCall */
    Default_Handler, /* DebugMon */
    0,
    Default_Handler, /* PendSV */
    SysTick_Handler,
    [16 ... 47] = External_IRQHandler, /* the mps2 boards' IRQs (the PIL image's UARTs) */
};
