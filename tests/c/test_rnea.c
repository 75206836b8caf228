/* The firmware's float32 RNEA against MuJoCo's own inverse dynamics (mj_inverse, double): the
 * general arm_rnea and the arm's generated kernel (gen/rnea_kernel.py), each on its own. */
#include <math.h>

#include "arm/rnea.h"
#include "arm_rnea_kernel.h"
#include "arm_robot_model_data.h"
#include "check.h"
#include "rnea_golden.h"

static void general(const float *q, const float *qd, const float *qdd, float *tau)
{
    arm_rnea(&ARM_ROBOT_MODEL, q, qd, qdd, tau);
}

static double worst_against_mujoco(const char *name,
                                   void (*rnea)(const float *, const float *, const float *, float *))
{
    double worst_rel = 0.0;
    for (int s = 0; s < RNEA_GOLDEN_COUNT; ++s) {
        float q[ARM_N_JOINTS], qd[ARM_N_JOINTS], qdd[ARM_N_JOINTS], tau[ARM_N_JOINTS];
        double scale = 0.0;
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            q[j] = (float)RNEA_GOLDEN_Q[s][j];
            qd[j] = (float)RNEA_GOLDEN_QD[s][j];
            qdd[j] = (float)RNEA_GOLDEN_QDD[s][j];
            scale = fmax(scale, fabs(RNEA_GOLDEN_TAU[s][j]));
        }
        rnea(q, qd, qdd, tau);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            /* Relative to the state's largest torque: float32 inputs carry ~1e-7 relative error. */
            const double rel = fabs((double)tau[j] - RNEA_GOLDEN_TAU[s][j]) / scale;
            worst_rel = fmax(worst_rel, rel);
            CHECK_MSG(rel < 1e-4, "%s: state %d joint %d: rnea %.9g mujoco %.9g", name, s, j,
                      (double)tau[j], RNEA_GOLDEN_TAU[s][j]);
        }
    }
    printf("%s vs mj_inverse over %d states: worst relative error %.3g\n", name, RNEA_GOLDEN_COUNT,
           worst_rel);
    return worst_rel;
}

int main(void)
{
    (void)worst_against_mujoco("rnea", general);
    (void)worst_against_mujoco("rnea kernel", arm_rnea_kernel);
    /* The controller takes the kernel for exactly this model, and arm_rnea for any other. */
    CHECK(arm_rnea_kernel_fits(&ARM_ROBOT_MODEL));
    arm_robot_model_t other = ARM_ROBOT_MODEL;
    other.link[ARM_N_JOINTS - 1].mass *= 1.1f;
    CHECK(!arm_rnea_kernel_fits(&other));
    other = ARM_ROBOT_MODEL;
    other.model_hash ^= 1u;
    CHECK(!arm_rnea_kernel_fits(&other));
    TEST_MAIN_END();
}
