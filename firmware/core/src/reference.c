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

int arm_move_plan(arm_move_t *m, const float from[ARM_N_JOINTS], const float to[ARM_N_JOINTS], float v_max,
                  float a_max)
{
    float d = 0.0f; /* the longest way any joint goes: it sets the pace for all */
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        m->q0[i] = from[i];
        m->dq[i] = to[i] - from[i];
        d = fabsf(m->dq[i]) > d ? fabsf(m->dq[i]) : d;
    }
    m->t_acc = m->t_total = m->s_acc = 0.0f;
    if (!(v_max > 0.0f && a_max > 0.0f && isfinite(v_max) && isfinite(a_max))) {
        for (int i = 0; i < ARM_N_JOINTS; ++i) m->dq[i] = 0.0f;
        return -1;
    }
    if (!(d > 0.0f) || !isfinite(d)) {
        for (int i = 0; i < ARM_N_JOINTS; ++i) m->dq[i] = isfinite(m->dq[i]) ? m->dq[i] : 0.0f;
        return 0; /* already there */
    }
    if (d >= v_max * v_max / a_max) { /* reaches v_max: accelerate, cruise, brake */
        m->t_acc = v_max / a_max;
        m->t_total = d / v_max + m->t_acc;
    } else { /* too short to reach v_max: accelerate, then brake */
        m->t_acc = sqrtf(d / a_max);
        m->t_total = 2.0f * m->t_acc;
    }
    m->s_acc = 1.0f / (m->t_acc * (m->t_total - m->t_acc));
    return 0;
}

void arm_move_eval(const arm_move_t *m, float t, float q_d[ARM_N_JOINTS], float qd_d[ARM_N_JOINTS],
                   float qdd_d[ARM_N_JOINTS])
{
    float s = 0.0f, sd = 0.0f, sdd = 0.0f; /* the normalised profile, 0 -> 1 */
    const float ta = m->t_acc, tt = m->t_total, a = m->s_acc;
    if (t >= tt) {
        s = 1.0f;
    } else if (t <= 0.0f) {
        s = 0.0f;
    } else if (t < ta) {
        s = 0.5f * a * t * t;
        sd = a * t;
        sdd = a;
    } else if (t <= tt - ta) {
        s = 0.5f * a * ta * ta + a * ta * (t - ta);
        sd = a * ta;
    } else {
        const float r = tt - t; /* the braking phase mirrors the accelerating one */
        s = 1.0f - 0.5f * a * r * r;
        sd = a * r;
        sdd = -a;
    }
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        q_d[i] = m->q0[i] + m->dq[i] * s;
        qd_d[i] = m->dq[i] * sd;
        qdd_d[i] = m->dq[i] * sdd;
    }
}

int arm_traj_init(arm_traj_t *tr, const float *t, const float *q, const float *qd, uint32_t n)
{
    tr->t = t;
    tr->q = q;
    tr->qd = qd;
    tr->n = 0u;
    tr->seg = 0u;
    if (n < 2u || t[0] != 0.0f) return -1;
    for (uint32_t k = 1; k < n; ++k) {
        if (!(t[k] > t[k - 1u])) return -1;
    }
    tr->n = n;
    return 0;
}

float arm_traj_duration(const arm_traj_t *tr)
{
    return tr->n >= 2u ? tr->t[tr->n - 1u] : 0.0f;
}

void arm_traj_eval(arm_traj_t *tr, float t, float q_d[ARM_N_JOINTS], float qd_d[ARM_N_JOINTS],
                   float qdd_d[ARM_N_JOINTS])
{
    const uint32_t n = tr->n;
    if (n < 2u || t >= tr->t[n - 1u] || t <= 0.0f) { /* before the start or after the end: a pose at rest */
        const uint32_t k = (n >= 2u && t > 0.0f) ? n - 1u : 0u;
        for (int i = 0; i < ARM_N_JOINTS; ++i) {
            q_d[i] = n > 0u ? tr->q[k * ARM_N_JOINTS + (uint32_t)i] : 0.0f;
            qd_d[i] = 0.0f;
            qdd_d[i] = 0.0f;
        }
        if (n >= 2u && t <= 0.0f) { /* the first knot's velocity stands (a trajectory may start moving) */
            for (int i = 0; i < ARM_N_JOINTS; ++i) qd_d[i] = tr->qd[i];
        }
        return;
    }
    if (t < tr->t[tr->seg]) tr->seg = 0u;
    while (tr->seg + 2u < n && t >= tr->t[tr->seg + 1u]) tr->seg++; /* bounded by n */
    const uint32_t k = tr->seg;
    const float h = tr->t[k + 1u] - tr->t[k];
    const float u = (t - tr->t[k]) / h, u2 = u * u, u3 = u2 * u;
    /* the Hermite basis, its first and second derivatives in u */
    const float h00 = 2.0f * u3 - 3.0f * u2 + 1.0f, h10 = u3 - 2.0f * u2 + u, h01 = -2.0f * u3 + 3.0f * u2,
                h11 = u3 - u2;
    const float d00 = 6.0f * u2 - 6.0f * u, d10 = 3.0f * u2 - 4.0f * u + 1.0f, d01 = -d00, d11 = 3.0f * u2 - 2.0f * u;
    const float s00 = 12.0f * u - 6.0f, s10 = 6.0f * u - 4.0f, s01 = -s00, s11 = 6.0f * u - 2.0f;
    const float *qa = tr->q + k * ARM_N_JOINTS, *qb = qa + ARM_N_JOINTS;
    const float *ma = tr->qd + k * ARM_N_JOINTS, *mb = ma + ARM_N_JOINTS;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        q_d[i] = h00 * qa[i] + h10 * h * ma[i] + h01 * qb[i] + h11 * h * mb[i];
        qd_d[i] = (d00 * qa[i] + d10 * h * ma[i] + d01 * qb[i] + d11 * h * mb[i]) / h;
        qdd_d[i] = (s00 * qa[i] + s10 * h * ma[i] + s01 * qb[i] + s11 * h * mb[i]) / (h * h);
    }
}
