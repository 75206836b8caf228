/* The firmware's float32 RNEA against MuJoCo's own inverse dynamics (mj_inverse, double). */
#include <math.h>

#include "arm/rnea.h"
#include "arm_robot_model_data.h"
#include "check.h"
#include "rnea_golden.h"

int main(void)
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
        arm_rnea(&ARM_ROBOT_MODEL, q, qd, qdd, tau);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            /* Relative to the state's largest torque: float32 inputs carry ~1e-7 relative error. */
            const double rel = fabs((double)tau[j] - RNEA_GOLDEN_TAU[s][j]) / scale;
            worst_rel = fmax(worst_rel, rel);
            CHECK_MSG(rel < 1e-4, "state %d joint %d: rnea %.9g mujoco %.9g", s, j, (double)tau[j],
                      RNEA_GOLDEN_TAU[s][j]);
        }
    }
    printf("rnea vs mj_inverse over %d states: worst relative error %.3g\n", RNEA_GOLDEN_COUNT,
           worst_rel);
    TEST_MAIN_END();
}
