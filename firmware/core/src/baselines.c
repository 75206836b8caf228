#include "arm/baselines.h"

#include <math.h>
#include <string.h>

void arm_tde_init(arm_tde_t *t, float period_s, float cutoff_hz)
{
    memset(t, 0, sizeof(*t));
    t->period_s = period_s;
    t->alpha = expf(-6.28318531f * cutoff_hz * period_s);
}

void arm_tde_output(arm_tde_t *t, const float qd[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS])
{
    (void)qd;
    memcpy(w_hat, t->w_hat, sizeof(t->w_hat));
}

void arm_tde_update(arm_tde_t *t, const float qd[ARM_N_JOINTS], const float a[ARM_N_JOINTS],
                    uint32_t hold_mask)
{
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if (t->primed && ((hold_mask >> j) & 1u) == 0u) {
            /* qd is this period's measurement: the last period's acceleration is now known. */
            const float qdd_prev = (qd[j] - t->qd_prev[j]) / t->period_s;
            const float raw = t->a_prev[j] - qdd_prev;
            t->w_hat[j] = t->alpha * t->w_hat[j] + (1.0f - t->alpha) * raw;
        }
        t->a_prev[j] = a[j];
        t->qd_prev[j] = qd[j];
    }
    t->primed = 1;
}

void arm_usde_smc_init(arm_usde_smc_t *u, float period_s, float k, float lambda, float eta,
                       float phi, float ks)
{
    memset(u, 0, sizeof(*u));
    u->k = k;
    u->alpha = expf(-period_s / k);
    u->lambda = lambda;
    u->eta = eta;
    u->phi = phi;
    u->ks = ks;
}

static float sat_unit(float x)
{
    return x > 1.0f ? 1.0f : (x < -1.0f ? -1.0f : x);
}

void arm_usde_smc_output(arm_usde_smc_t *u, const float e[ARM_N_JOINTS],
                         const float e_dot[ARM_N_JOINTS], const float qd[ARM_N_JOINTS],
                         float u_o[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS])
{
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if (!u->primed) {
            /* Start the filters at the first measurement: no start-up transient in w_hat. */
            u->x_f[j] = qd[j];
            u->a_f[j] = 0.0f;
        }
        w_hat[j] = u->a_f[j] - (qd[j] - u->x_f[j]) / u->k;
        u->w_hat[j] = w_hat[j];
        const float s = e_dot[j] + u->lambda * e[j];
        u_o[j] = -u->lambda * e_dot[j] - u->eta * sat_unit(s / u->phi) - u->ks * s;
    }
    u->primed = 1;
}

void arm_usde_smc_update(arm_usde_smc_t *u, const float qd[ARM_N_JOINTS],
                         const float a[ARM_N_JOINTS], uint32_t hold_mask)
{
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        u->x_f[j] = u->alpha * u->x_f[j] + (1.0f - u->alpha) * qd[j];
        if (((hold_mask >> j) & 1u) == 0u) {
            u->a_f[j] = u->alpha * u->a_f[j] + (1.0f - u->alpha) * a[j];
        } else {
            /* Anti-windup: what the limiter removed is not disturbance; hold the estimate. */
            u->a_f[j] = u->w_hat[j] + (qd[j] - u->x_f[j]) / u->k;
        }
    }
}
