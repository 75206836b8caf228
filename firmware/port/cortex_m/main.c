/* The Cortex-M golden-vector image: the portable core on the target CPU, checked against
 *  1. MuJoCo's inverse dynamics (rnea_golden.h, gen/robot_model.py), the host test's vectors;
 *  2. a closed-loop run of arm_ctl_step for every method, as the host build computed it
 *     (closed_loop_golden.h, tests/c/gen_closed_loop_golden.c).
 * Prints through semihosting; the exit code is the verdict (0 = pass). */
#include <math.h>
#include <stdint.h>

#include "arm/rnea.h"
#include "arm_rnea_kernel.h"
#include "arm_robot_model_data.h"
#include "closed_loop.h"
#include "closed_loop_golden.h"
#include "rnea_golden.h"
#include "semihost.h"
#include "step_count.h"

#ifndef ARM_MCU_NAME
#define ARM_MCU_NAME "cortex-m"
#endif

/* float32 on two compilers and two libm's (glibc vs newlib sinf/cosf/sqrtf): the same arithmetic
 * up to last-bit differences, which the closed loop carries along but does not amplify. */
#ifndef RNEA_TOL_REL
#define RNEA_TOL_REL 1e-4f /* as tests/c/test_rnea.c on the host */
#endif
#ifndef CL_TOL_REL
#define CL_TOL_REL 1e-4f /* of the case's largest torque; measured: <= 1e-5 (M4, M3), 0 (M7) */
#endif

uint32_t stack_high_water(void); /* startup.c */

/* the general arm_rnea (kernel 0) and the arm's generated kernel (1), each against MuJoCo's
 * vectors (a flag, not a function pointer: the stack analysis refuses indirect calls) */
static int check_rnea(const char *name, int kernel)
{
    float worst = 0.0f;
    int bad = 0;
    for (int s = 0; s < RNEA_GOLDEN_COUNT; ++s) {
        float q[ARM_N_JOINTS], qd[ARM_N_JOINTS], qdd[ARM_N_JOINTS], tau[ARM_N_JOINTS];
        float scale = 0.0f;
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            q[j] = (float)RNEA_GOLDEN_Q[s][j];
            qd[j] = (float)RNEA_GOLDEN_QD[s][j];
            qdd[j] = (float)RNEA_GOLDEN_QDD[s][j];
            scale = fmaxf(scale, fabsf((float)RNEA_GOLDEN_TAU[s][j]));
        }
        if (kernel) {
            arm_rnea_kernel(q, qd, qdd, tau);
        } else {
            arm_rnea(&ARM_ROBOT_MODEL, q, qd, qdd, tau);
        }
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            const float rel = fabsf(tau[j] - (float)RNEA_GOLDEN_TAU[s][j]) / scale;
            worst = fmaxf(worst, rel);
            if (!(rel < RNEA_TOL_REL)) {
                ++bad;
            }
        }
    }
    sh_puts(name);
    sh_puts(": ");
    sh_put_u32((uint32_t)RNEA_GOLDEN_COUNT);
    sh_puts(" states vs mj_inverse, worst relative error ");
    sh_put_sci(worst);
    sh_puts(bad ? " FAIL\n" : " ok\n");
    return bad;
}

static int check_closed_loop(void)
{
    static cl_result_t r;
    int bad_cases = 0;
    for (int c = 0; c < CL_GOLDEN_CASES; ++c) {
        const cl_golden_t *g = &CL_GOLDEN[c];
        const cl_case_t cs = {.method = (arm_method_t)g->method, .numeric = (arm_numeric_t)g->numeric};
        cl_run(&ARM_ROBOT_MODEL, ARM_HOME_Q, &cs, &r);
        float scale = 0.0f, worst = 0.0f;
        for (unsigned k = 0; k < CL_RECORDS; ++k) {
            for (int j = 0; j < ARM_N_JOINTS; ++j) {
                scale = fmaxf(scale, fabsf(g->tau[k][j]));
            }
        }
        int ok = r.init_result == g->init_result && r.final_state == g->final_state;
        for (unsigned k = 0; k < CL_RECORDS; ++k) {
            for (int j = 0; j < ARM_N_JOINTS; ++j) {
                const float rel = fabsf(r.tau[k][j] - g->tau[k][j]) / (scale > 0.0f ? scale : 1.0f);
                worst = rel > worst || rel != rel ? rel : worst;
            }
        }
        ok = ok && worst <= CL_TOL_REL;
        bad_cases += !ok;
        sh_puts("closed loop: ");
        sh_puts(arm_method_str(cs.method));
        sh_puts(cs.numeric == ARM_NUMERIC_FIXED ? " fixed" : " float");
        sh_puts(", ");
        sh_put_u32(CL_STEPS);
        sh_puts(" steps, torque worst relative deviation from host ");
        sh_put_sci(worst);
        sh_puts(", final state ");
        sh_puts(arm_state_str((arm_state_t)r.final_state));
        sh_puts(ok ? " ok\n" : " FAIL\n");
    }
    return bad_cases;
}

int main(void)
{
    sh_puts("cortex-m golden vectors on " ARM_MCU_NAME "\n");
    const int bad = check_rnea("rnea", 0) + check_rnea("rnea kernel", 1) + check_closed_loop();
    (void)report_step_cost();
    sh_puts("stack high-water mark (measured): ");
    sh_put_u32(stack_high_water());
    sh_puts(" bytes\n");
    sh_puts(bad == 0 ? "RESULT: PASS\n" : "RESULT: FAIL\n");
    return bad == 0 ? 0 : 1;
}
