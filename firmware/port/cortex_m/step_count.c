/* SysTick-based cost of the control step (step_count.h). Each figure is the difference of two
 * runs of different length, so the set-up and the loop around the call cancel. */
#include "step_count.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "arm/controller.h"
#include "arm/rnea.h"
#include "arm_rnea_kernel.h"
#include "arm_robot_model_data.h"
#include "semihost.h"

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SYST_MASK 0x00FFFFFFu /* a 24-bit down-counter */

#define SHORT_RUN 50u
#define LONG_RUN 250u /* 200 calls measured: well inside the counter's 2^24 ticks */

static void systick_start(void)
{
    SYST_CSR = 0u;
    SYST_RVR = SYST_MASK;
    SYST_CVR = 0u;       /* any write clears it: the count restarts from the reload value */
    SYST_CSR = 0x5u;     /* enable, core clock, no interrupt */
}

static uint32_t systick_now(void) { return SYST_CVR & SYST_MASK; }

static uint32_t elapsed(uint32_t start, uint32_t end) { return (start - end) & SYST_MASK; }

/* 2 n instructions (subs, bne) and nothing else: the calibration of a tick */
static __attribute__((noinline)) void spin(uint32_t n)
{
    __asm__ volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
}

static uint32_t ticks_spin(uint32_t n)
{
    const uint32_t t0 = systick_now();
    spin(n);
    return elapsed(t0, systick_now());
}

static void fill(uint32_t k, arm_ctl_input_t *in)
{
    const float t = 0.001f * (float)k; /* the host benchmark's inputs (tests/bench/bench_step.cpp) */
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        in->q[j] = 0.5f * sinf(t + (float)j);
        in->qd[j] = 0.5f * cosf(t + (float)j);
        in->q_d[j] = in->q[j] + 0.01f;
        in->qd_d[j] = in->qd[j];
        in->qdd_d[j] = 0.1f;
    }
    in->fresh_mask = (1u << ARM_N_JOINTS) - 1u;
}

typedef enum { RUN_NOTHING, RUN_STEP, RUN_KERNEL, RUN_GENERAL } what_t;

static arm_ctl_t g_ctl;
static volatile float g_sink;

static uint32_t ticks_run(what_t what, uint32_t calls, int *state_ok)
{
    arm_ctl_config_t cfg;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.method = ARM_METHOD_PM;
    cfg.numeric = ARM_NUMERIC_FLOAT;
    *state_ok = arm_ctl_init(&g_ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_OK;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    memset(&in, 0, sizeof(in));
    memset(&out, 0, sizeof(out));
    const uint32_t t0 = systick_now();
    for (uint32_t k = 0; k < calls; ++k) {
        fill(k, &in);
        switch (what) {
        case RUN_STEP:
            arm_ctl_step(&g_ctl, &in, &out);
            memcpy(in.tau_measured, out.tau, sizeof(in.tau_measured)); /* drives that do as told */
            break;
        case RUN_KERNEL: arm_rnea_kernel(in.q, in.qd, in.qdd_d, out.tau); break;
        case RUN_GENERAL: arm_rnea(&ARM_ROBOT_MODEL, in.q, in.qd, in.qdd_d, out.tau); break;
        case RUN_NOTHING: break;
        }
        g_sink = out.tau[0];
    }
    const uint32_t t = elapsed(t0, systick_now());
    if (what == RUN_STEP) {
        *state_ok = *state_ok && out.state == ARM_STATE_RUNNING; /* measured the running step */
    }
    return t;
}

/* ticks per call of `what`, the same loop without the call subtracted */
static float ticks_per_call(what_t what, int *ok)
{
    int s1 = 1, s2 = 1, s3 = 1, s4 = 1;
    const float with = (float)(ticks_run(what, LONG_RUN, &s1) - ticks_run(what, SHORT_RUN, &s2));
    const float without = (float)(ticks_run(RUN_NOTHING, LONG_RUN, &s3) - ticks_run(RUN_NOTHING, SHORT_RUN, &s4));
    *ok = s1 && s2;
    return (with - without) / (float)(LONG_RUN - SHORT_RUN);
}

static void put_f1(float v) /* one decimal, no printf */
{
    const uint32_t tenths = (uint32_t)(v * 10.0f + 0.5f);
    sh_put_u32(tenths / 10u);
    sh_puts(".");
    sh_put_u32(tenths % 10u);
}

int report_step_cost(void)
{
    systick_start();
    const uint32_t n1 = 10000u, n2 = 110000u;
    const float spin_ticks = (float)(ticks_spin(n2) - ticks_spin(n1));
    const float instr_per_tick = 2.0f * (float)(n2 - n1) / spin_ticks;
    sh_puts("step cost: instructions per SysTick tick (calibrated by a loop of known length) ");
    put_f1(instr_per_tick);
    sh_puts("\n");
    static const struct {
        what_t what;
        const char *name;
    } rows[] = {{RUN_STEP, "pm step (float)"}, {RUN_KERNEL, "rnea kernel"}, {RUN_GENERAL, "rnea general"}};
    for (unsigned r = 0; r < sizeof(rows) / sizeof(rows[0]); ++r) {
        int ok = 1;
        const float ticks = ticks_per_call(rows[r].what, &ok);
        sh_puts("step cost: ");
        sh_puts(rows[r].name);
        sh_puts(": ticks per call ");
        put_f1(ticks);
        sh_puts(", instructions per call ");
        put_f1(ticks * instr_per_tick);
        sh_puts(ok ? "\n" : " (the step did not stay running: not a figure)\n");
    }
    SYST_CSR = 0u;
    return 0;
}
