/* The joint states the inverse dynamics is compared and counted on (bench_rnea.cpp, and
 * tests/c/rnea/rnea_torques.c, which test_bench_rnea.py compares with Pinocchio's Python rnea):
 * the inputs of bench_step's steps, state k at t = 1 ms * k. C and C++. */
#ifndef ARM_RNEA_STATES_H
#define ARM_RNEA_STATES_H

#include <math.h>

#include "arm_robot_dims.h"

#define ARM_RNEA_CHECK_STATES 200 /* the agreement check's states: state(ARM_RNEA_CHECK_STRIDE * k) */
#define ARM_RNEA_CHECK_STRIDE 37

static inline void arm_rnea_state(int k, float q[ARM_N_JOINTS], float qd[ARM_N_JOINTS], float qdd[ARM_N_JOINTS])
{
    const float t = 0.001f * (float)k;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        q[j] = 0.5f * sinf(t + (float)j);
        qd[j] = 0.5f * cosf(t + (float)j);
        qdd[j] = 0.1f + 0.3f * sinf(3.0f * t + (float)j);
    }
}

#endif
