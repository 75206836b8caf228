#include "arm/reference.h"

#include <math.h>

#include "arm_params.h"

#define ARM_TWO_PI 6.28318531f

void arm_reference_set_hold(arm_reference_t *ref, float hold_s)
{
    ref->hold_s = hold_s;
}

void arm_reference_default(arm_reference_t *ref, const float q0[ARM_N_JOINTS])
{
    ref->hold_s = 0.0f;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        /* Distinct, incommensurate frequencies so the joints excite each other's coupling. */
        const float k = (float)i;
        ref->q0[i] = q0[i];
        ref->amp[i] = (float)ARM_P_DEFAULT_REFERENCE_AMP_BASE + (float)ARM_P_DEFAULT_REFERENCE_AMP_STEP * k;
        ref->omega[i] = ARM_TWO_PI * ((float)ARM_P_DEFAULT_REFERENCE_FREQ_BASE_HZ +
                                      (float)ARM_P_DEFAULT_REFERENCE_FREQ_STEP_HZ * k);
    }
}

void arm_reference_set(arm_reference_t *ref, const float q0[ARM_N_JOINTS],
                       const float amp[ARM_N_JOINTS], const float freq_hz[ARM_N_JOINTS])
{
    ref->hold_s = 0.0f;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        ref->q0[i] = q0[i];
        ref->amp[i] = amp[i];
        ref->omega[i] = ARM_TWO_PI * freq_hz[i];
    }
}

void arm_reference_eval(const arm_reference_t *ref, float t, float q_d[ARM_N_JOINTS],
                        float qd_d[ARM_N_JOINTS], float qdd_d[ARM_N_JOINTS])
{
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float wt = t < ref->hold_s ? 0.0f : ref->omega[i] * (t - ref->hold_s);
        const float a = ref->amp[i];
        const float w = ref->omega[i];
        q_d[i] = ref->q0[i] + a * (1.0f - cosf(wt));
        qd_d[i] = a * w * sinf(wt);
        qdd_d[i] = t < ref->hold_s ? 0.0f : a * w * w * cosf(wt);
    }
}
