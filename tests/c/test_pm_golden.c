/* The firmware's estimator/controller blocks against gen.golden's vectors (10,000 periods):
 * float32 within 1e-5 of a double-precision run of the same tables, fixed point bit-exact with
 * an integer model of the arithmetic pm_design_fixed.h prescribes. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "arm/pm.h"
#include "check.h"

#define COLS 15
#define MAX_STEPS 10000

static float g_data[MAX_STEPS][COLS];

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s pm_golden.bin\n", argv[0]);
        return 2;
    }
    FILE *f = fopen(argv[1], "rb");
    if (f == NULL) {
        fprintf(stderr, "cannot open %s\n", argv[1]);
        return 2;
    }
    const size_t steps = fread(g_data, sizeof(g_data[0]), MAX_STEPS, f);
    fclose(f);
    CHECK(steps == MAX_STEPS);

    static const arm_pm_structure_t structures[3] = {ARM_PM_DECOUPLED, ARM_PM_PAPER,
                                                     ARM_PM_NO_ESTIMATOR};
    static const char *const names[3] = {"decoupled", "paper", "none"};
    for (int s = 0; s < 3; ++s) {
        for (int numeric = 0; numeric < 2; ++numeric) {
            static arm_pm_t pm;
            arm_pm_init(&pm, &arm_pm_builtin_design, numeric ? ARM_NUMERIC_FIXED : ARM_NUMERIC_FLOAT, structures[s]);
            const int col = 3 + 4 * s + 2 * numeric;
            double scale[2] = {0.0, 0.0};
            for (size_t k = 0; k < steps; ++k) {
                scale[0] = fmax(scale[0], fabs((double)g_data[k][col]));
                scale[1] = fmax(scale[1], fabs((double)g_data[k][col + 1]));
            }
            CHECK_MSG(scale[0] > 0.0, "%s: the golden u_o column is all zeros (a golden of nothing)", names[s]);
            double worst[2] = {0.0, 0.0};
            long mismatches = 0;
            for (size_t k = 0; k < steps; ++k) {
                float e[ARM_N_JOINTS], e_dot[ARM_N_JOINTS], u_o[ARM_N_JOINTS], w_hat[ARM_N_JOINTS];
                for (int j = 0; j < ARM_N_JOINTS; ++j) {
                    e[j] = g_data[k][0];
                    e_dot[j] = g_data[k][1];
                }
                arm_pm_output(&pm, e, e_dot, u_o, w_hat);
                for (int j = 0; j < ARM_N_JOINTS; ++j) {
                    const float got[2] = {u_o[j], w_hat[j]};
                    for (int o = 0; o < 2; ++o) {
                        const double want = (double)g_data[k][col + o];
                        if (numeric) {
                            mismatches += got[o] != (float)want;
                        } else {
                            /* relative to the column's largest value; a column of zeros (w_hat
                             * without an estimator) must come out zeros: absolute */
                            const double err = fabs((double)got[o] - want);
                            worst[o] = fmax(worst[o], scale[o] > 0.0 ? err / scale[o] : err);
                        }
                    }
                }
                arm_pm_update(&pm, g_data[k][2] != 0.0f ? 0x3Fu : 0u);
            }
            if (numeric) {
                CHECK_MSG(mismatches == 0, "%s fixed: %ld outputs differ from the integer model",
                          names[s], mismatches);
                printf("%-9s fixed: bit-exact over %zu periods x %d joints\n", names[s], steps,
                       ARM_N_JOINTS);
            } else {
                CHECK_MSG(worst[0] < 1e-5 && worst[1] < 1e-5,
                          "%s float: worst relative error u_o %.3g w_hat %.3g", names[s], worst[0],
                          worst[1]);
                printf("%-9s float: worst relative error u_o %.3g, w_hat %.3g (of max |u_o| %.4g, "
                       "|w_hat| %.4g)\n",
                       names[s], worst[0], worst[1], scale[0], scale[1]);
            }
        }
    }
    TEST_MAIN_END();
}
