#include "mcu_clock.h"

#include "loop_port.h"
#include "mcu_uart.h"

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SCB_ICSR (*(volatile uint32_t *)0xE000ED04u)
#define ICSR_PENDSTSET (1u << 26)
#define TICKS_PER_MS (MCU_SYSCLK_HZ / 1000u)
#define NS_PER_TICK (1000000000u / MCU_SYSCLK_HZ)
#define POLL_INSTRUCTIONS 4u

const int port_paces_lockstep = 1;

static volatile uint32_t g_ms;
static uint32_t g_step_instructions;
static uint32_t g_per_tick;
static int32_t g_overhead; /* the measurement's own instructions, found by calibration */

void SysTick_Handler(void)
{
    g_ms++;
}

/* The loop's clock: SysTick's count (QEMU's virtual time under -icount: the image's own time,
 * which runs slower than the host's while it computes and at the host's pace while it sleeps). */
int64_t port_clock_ns(void)
{
    return systick_ns();
}

int64_t systick_ns(void)
{
    const uint32_t m = mcu_irq_save();
    uint32_t ms = g_ms;
    uint32_t cvr = SYST_CVR;
    if ((SCB_ICSR & ICSR_PENDSTSET) != 0u) { /* wrapped, its interrupt not yet taken */
        cvr = SYST_CVR;
        ms++;
    }
    mcu_irq_restore(m);
    return (int64_t)ms * 1000000 + (int64_t)(TICKS_PER_MS - 1u - cvr) * NS_PER_TICK;
}

void port_clock_sleep_until(int64_t t_ns)
{
    while (port_clock_ns() < t_ns) {
        __asm__ volatile("wfi");
    }
}

/* Spins until the counter moves on: returns its new value, a few instructions after the edge. */
static inline uint32_t next_edge(void)
{
    const uint32_t c0 = SYST_CVR;
    uint32_t c;
    while ((c = SYST_CVR) == c0) {
    }
    return c;
}

/* Ticks from edge `from` to the edge at `to` (the counter counts down and reloads every ms). */
static inline uint32_t ticks_between(uint32_t from, uint32_t to)
{
    return (from + TICKS_PER_MS - to) % TICKS_PER_MS;
}

/* 2 n instructions (subs, bne) and nothing else */
static __attribute__((noinline)) void spin(uint32_t n)
{
    __asm__ volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
}

typedef enum { WORK_STEP, WORK_SPIN } work_t;

/* Instructions from one edge to the edge after the work, minus the polls after it, less the
 * overhead: the work's own instructions. Interrupts are masked throughout (an interrupt during
 * the step would count its own instructions). */
static __attribute__((noinline)) uint32_t measure(work_t what, uint32_t n, arm_ctl_t *ctl,
                                                  const arm_ctl_input_t *in, arm_ctl_output_t *out)
{
    const uint32_t m = mcu_irq_save();
    const uint32_t start = next_edge();
    if (what == WORK_STEP) {
        arm_ctl_step(ctl, in, out);
    } else {
        spin(n);
    }
    /* polls of the counter until its next edge: exactly POLL_INSTRUCTIONS each (written out, so no
     * compiler decides the loop's length) */
    uint32_t polls = 0u, end;
    const uint32_t c0 = SYST_CVR;
    __asm__ volatile("1: ldr %1, [%2]\n\t"
                     "adds %0, %0, #1\n\t"
                     "cmp %1, %3\n\t"
                     "beq 1b"
                     : "+r"(polls), "=&r"(end)
                     : "r"(&SYST_CVR), "r"(c0)
                     : "cc", "memory");
    mcu_irq_restore(m);
    const int32_t total = (int32_t)(ticks_between(start, end) * g_per_tick) - (int32_t)(polls * POLL_INSTRUCTIONS);
    return (uint32_t)(total - g_overhead);
}

void mcu_clock_start(void)
{
    SYST_CSR = 0u;
    SYST_RVR = TICKS_PER_MS - 1u;
    SYST_CVR = 0u;
    SYST_CSR = 0x7u; /* core clock, interrupt, enable */
    /* a tick in instructions, by a loop of known length (QEMU -icount shift=0: 40) */
    const uint32_t m = mcu_irq_save();
    uint32_t a = next_edge();
    spin(5000u);
    uint32_t b = next_edge();
    uint32_t c = next_edge();
    spin(15000u);
    uint32_t d = next_edge();
    mcu_irq_restore(m);
    const uint32_t t1 = ticks_between(a, b), t2 = ticks_between(c, d);
    g_per_tick = t2 > t1 ? (2u * 10000u + (t2 - t1) / 2u) / (t2 - t1) : 1u;
    /* the measurement's overhead: what it counts for a work of known length */
    g_overhead = 0;
    const uint32_t known = 2u * 2000u;
    g_overhead = (int32_t)measure(WORK_SPIN, 2000u, 0, 0, 0) - (int32_t)known;
}

void port_control_step(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out)
{
    g_step_instructions = measure(WORK_STEP, 0u, ctl, in, out);
}

uint32_t mcu_last_step_instructions(void)
{
    return g_step_instructions;
}

uint32_t mcu_instructions_per_tick(void)
{
    return g_per_tick;
}
