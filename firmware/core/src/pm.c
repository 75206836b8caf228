#include "arm/pm.h"

#include <math.h>
#include <string.h>

/* Both headers define the same ARM_DESIGN_* macros; a mismatching pair is a macro redefinition,
 * which the warning flags turn into a build error: the compile-time half of the header check. */
#include "pm_design_fixed.h"
#include "pm_design_float.h"

/* ---- float32 ----------------------------------------------------------------------------- */

static float est_output_f(const float x[ARM_EST_NX], const float v[2])
{
    float acc = ARM_EST_D[0][0] * v[0] + ARM_EST_D[0][1] * v[1];
    for (int i = 0; i < ARM_EST_NX; ++i) {
        acc += ARM_EST_C[0][i] * x[i];
    }
    return acc;
}

static float ctl_output_f(const float x[ARM_CTL_NX], const float y[2])
{
    float acc = ARM_CTL_D[0][0] * y[0] + ARM_CTL_D[0][1] * y[1];
    for (int i = 0; i < ARM_CTL_NX; ++i) {
        acc += ARM_CTL_C[0][i] * x[i];
    }
    return acc;
}

static void est_update_f(float x[ARM_EST_NX], const float v[2])
{
    float next[ARM_EST_NX];
    for (int i = 0; i < ARM_EST_NX; ++i) {
        float acc = ARM_EST_B[i][0] * v[0] + ARM_EST_B[i][1] * v[1];
        for (int j = 0; j < ARM_EST_NX; ++j) {
            acc += ARM_EST_A[i][j] * x[j];
        }
        next[i] = acc;
    }
    memcpy(x, next, sizeof(next));
}

static void ctl_update_f(float x[ARM_CTL_NX], const float y[2])
{
    float next[ARM_CTL_NX];
    for (int i = 0; i < ARM_CTL_NX; ++i) {
        float acc = ARM_CTL_B[i][0] * y[0] + ARM_CTL_B[i][1] * y[1];
        for (int j = 0; j < ARM_CTL_NX; ++j) {
            acc += ARM_CTL_A[i][j] * x[j];
        }
        next[i] = acc;
    }
    memcpy(x, next, sizeof(next));
}

static void im_update_f(float x[2], float u)
{
    const float x0 = ARM_IM_A[0][0] * x[0] + ARM_IM_A[0][1] * x[1] + ARM_IM_B[0][0] * u;
    const float x1 = ARM_IM_A[1][0] * x[0] + ARM_IM_A[1][1] * x[1] + ARM_IM_B[1][0] * u;
    x[0] = x0;
    x[1] = x1;
}

/* ---- fixed point: exactly the arithmetic pm_design_fixed.h prescribes --------------------- */

static int32_t sat32(int64_t v)
{
    return v > 2147483647LL ? 2147483647 : (v < -2147483647LL ? -2147483647 : (int32_t)v);
}

static int32_t round_shift(int64_t acc, int shift)
{
    if (shift == 0) {
        return sat32(acc);
    }
    return sat32((acc + ((int64_t)1 << (shift - 1))) >> shift);
}

static int32_t sat_range(int32_t v, int32_t lim)
{
    return v > lim ? lim : (v < -lim ? -lim : v);
}

static int32_t to_q(float v, int frac, int32_t lim)
{
    /* lrintf would round half to even; the proof only needs |error| <= 1/2 LSB either way. */
    const float scaled = v * (float)(1LL << frac);
    if (!(scaled < 2147483520.0f)) return lim; /* also catches NaN: the safety layer stops first */
    if (!(scaled > -2147483520.0f)) return -lim;
    return sat_range((int32_t)lrintf(scaled), lim);
}

static float from_q(int32_t v, int frac)
{
    return (float)v / (float)(1LL << frac);
}

static int32_t est_output_q(const int32_t x[ARM_EST_NX], const int32_t v[2])
{
    int64_t acc = (int64_t)ARM_EST_D_Q[0][0] * v[0] + (int64_t)ARM_EST_D_Q[0][1] * v[1];
    for (int i = 0; i < ARM_EST_NX; ++i) {
        acc += (int64_t)ARM_EST_C_Q[0][i] * x[i];
    }
    return round_shift(acc, ARM_EST_ACC_U_SHIFT);
}

static int32_t ctl_output_q(const int32_t x[ARM_CTL_NX], const int32_t y[2])
{
    int64_t acc = (int64_t)ARM_CTL_D_Q[0][0] * y[0] + (int64_t)ARM_CTL_D_Q[0][1] * y[1];
    for (int i = 0; i < ARM_CTL_NX; ++i) {
        acc += (int64_t)ARM_CTL_C_Q[0][i] * x[i];
    }
    return round_shift(acc, ARM_CTL_ACC_U_SHIFT);
}

static void est_update_q(int32_t x[ARM_EST_NX], const int32_t v[2])
{
    int32_t next[ARM_EST_NX];
    for (int i = 0; i < ARM_EST_NX; ++i) {
        int64_t acc = (int64_t)ARM_EST_B_Q[i][0] * v[0] + (int64_t)ARM_EST_B_Q[i][1] * v[1];
        for (int j = 0; j < ARM_EST_NX; ++j) {
            acc += (int64_t)ARM_EST_A_Q[i][j] * x[j];
        }
        next[i] = round_shift(acc, ARM_EST_ACC_X_SHIFT);
    }
    memcpy(x, next, sizeof(next));
}

static void ctl_update_q(int32_t x[ARM_CTL_NX], const int32_t y[2])
{
    int32_t next[ARM_CTL_NX];
    for (int i = 0; i < ARM_CTL_NX; ++i) {
        int64_t acc = (int64_t)ARM_CTL_B_Q[i][0] * y[0] + (int64_t)ARM_CTL_B_Q[i][1] * y[1];
        for (int j = 0; j < ARM_CTL_NX; ++j) {
            acc += (int64_t)ARM_CTL_A_Q[i][j] * x[j];
        }
        next[i] = round_shift(acc, ARM_CTL_ACC_X_SHIFT);
    }
    memcpy(x, next, sizeof(next));
}

static void im_update_q(int32_t x[2], int32_t u)
{
    const int64_t a0 = (int64_t)ARM_IM_A_Q[0][0] * x[0] + (int64_t)ARM_IM_A_Q[0][1] * x[1] +
                       (int64_t)ARM_IM_B_Q[0][0] * u;
    const int64_t a1 = (int64_t)ARM_IM_A_Q[1][0] * x[0] + (int64_t)ARM_IM_A_Q[1][1] * x[1] +
                       (int64_t)ARM_IM_B_Q[1][0] * u;
    x[0] = sat_range(round_shift(a0, ARM_IM_ACC_X_SHIFT), ARM_IM_E_MAX_Q);
    x[1] = sat_range(round_shift(a1, ARM_IM_ACC_X_SHIFT), ARM_IM_E_DOT_MAX_Q);
}

/* ---- interface ----------------------------------------------------------------------------- */

void arm_pm_init(arm_pm_t *pm, arm_numeric_t numeric, arm_pm_structure_t structure)
{
    memset(pm, 0, sizeof(*pm));
    pm->numeric = numeric;
    pm->structure = structure;
}

void arm_pm_output(arm_pm_t *pm, const float e[ARM_N_JOINTS], const float e_dot[ARM_N_JOINTS],
                   float u_o[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS])
{
    const int with_estimator = pm->structure != ARM_PM_NO_ESTIMATOR;
    const int decoupled = pm->structure == ARM_PM_DECOUPLED;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if (pm->numeric == ARM_NUMERIC_FLOAT) {
            float *y = pm->s.f.y[j];
            float *v = pm->s.f.v[j];
            y[0] = e[j];
            y[1] = e_dot[j];
            if (!pm->primed) {
                pm->s.f.im[j][0] = y[0];
                pm->s.f.im[j][1] = y[1];
            }
            pm->s.f.u_o[j] = ctl_output_f(pm->s.f.ctl[j], y);
            v[0] = decoupled ? y[0] - pm->s.f.im[j][0] : y[0];
            v[1] = decoupled ? y[1] - pm->s.f.im[j][1] : y[1];
            u_o[j] = pm->s.f.u_o[j];
            w_hat[j] = with_estimator ? est_output_f(pm->s.f.est[j], v) : 0.0f;
        } else {
            int32_t *y = pm->s.q.y[j];
            int32_t *v = pm->s.q.v[j];
            y[0] = to_q(e[j], ARM_Y_FRAC, ARM_RANGE_E_MAX_Q);
            y[1] = to_q(e_dot[j], ARM_Y_FRAC, ARM_RANGE_E_DOT_MAX_Q);
            if (!pm->primed) {
                pm->s.q.im[j][0] = y[0];
                pm->s.q.im[j][1] = y[1];
            }
            pm->s.q.u_o[j] = ctl_output_q(pm->s.q.ctl[j], y);
            v[0] = decoupled ? sat_range(y[0] - pm->s.q.im[j][0], ARM_RANGE_E_MAX_Q) : y[0];
            v[1] = decoupled ? sat_range(y[1] - pm->s.q.im[j][1], ARM_RANGE_E_DOT_MAX_Q) : y[1];
            u_o[j] = from_q(pm->s.q.u_o[j], ARM_CTL_U_FRAC);
            w_hat[j] = with_estimator ? from_q(est_output_q(pm->s.q.est[j], v), ARM_EST_U_FRAC)
                                      : 0.0f;
        }
    }
    pm->primed = 1;
}

void arm_pm_update(arm_pm_t *pm, uint32_t hold_mask)
{
    const int with_estimator = pm->structure != ARM_PM_NO_ESTIMATOR;
    const int decoupled = pm->structure == ARM_PM_DECOUPLED;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const int hold = (hold_mask >> j) & 1u;
        if (pm->numeric == ARM_NUMERIC_FLOAT) {
            ctl_update_f(pm->s.f.ctl[j], pm->s.f.y[j]);
            if (with_estimator && !hold) {
                est_update_f(pm->s.f.est[j], pm->s.f.v[j]);
                if (decoupled) im_update_f(pm->s.f.im[j], pm->s.f.u_o[j]);
            } else if (decoupled && hold) {
                /* Anti-windup: while the limiter decides the torque, K is held and the internal
                 * model follows the measured error, so K does not learn the limiter as w. */
                pm->s.f.im[j][0] = pm->s.f.y[j][0];
                pm->s.f.im[j][1] = pm->s.f.y[j][1];
            }
        } else {
            ctl_update_q(pm->s.q.ctl[j], pm->s.q.y[j]);
            if (with_estimator && !hold) {
                est_update_q(pm->s.q.est[j], pm->s.q.v[j]);
                if (decoupled) im_update_q(pm->s.q.im[j], pm->s.q.u_o[j]);
            } else if (decoupled && hold) {
                pm->s.q.im[j][0] = pm->s.q.y[j][0];
                pm->s.q.im[j][1] = pm->s.q.y[j][1];
            }
        }
    }
}

const char *arm_pm_design_hash(void)
{
    return ARM_DESIGN_HASH;
}

int arm_pm_check_design(float loop_rate_hz)
{
    return fabsf(loop_rate_hz - (float)ARM_LOOP_RATE_HZ) <= 1e-3f * (float)ARM_LOOP_RATE_HZ ? 0 : -1;
}
