#include "arm/pm.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

/* Both headers define the same ARM_DESIGN_* macros; a mismatching pair is a macro redefinition,
 * which the warning flags turn into a build error: the compile-time half of the header check. */
#include "pm_design_fixed.h"
#include "pm_design_float.h"

/* The blocks are written once, for any dimensions, and inlined twice: for the built-in design,
 * whose dimensions and tables are compile-time constants (the compiler unrolls every loop to the
 * design's own state size, folds its numbers in and drops padding states: pm_design_*.h's inert
 * state of a static gain), and, where designs are loaded at run time (ARM_PM_RUNTIME_DESIGNS), for
 * any other design, read through arm_pm_design_t. Both run the same operations in the same order:
 * the same design gives the same numbers either way (a padding state's 0 * 0 is not added, which
 * can only turn an exact -0 into +0). */
#if defined(__GNUC__) || defined(__clang__)
#define PM_INLINE static inline __attribute__((always_inline))
#else
#define PM_INLINE static inline
#endif

/* ---- float32 ----------------------------------------------------------------------------- */

/* One system's tables and dimension: K's or C's, float or fixed (the same code runs both). */
typedef struct {
    int nx;
    const float *a, *b, *c, *d;
} sys_f_t;

typedef struct {
    int nx;
    const int32_t *a, *b, *c, *d;
    int acc_x_shift, acc_u_shift;
} sys_q_t;

PM_INLINE sys_f_t est_f(const arm_pm_design_t *d)
{
    const sys_f_t s = {d->est_nx, d->est_a, d->est_b, d->est_c, d->est_d};
    return s;
}

PM_INLINE sys_f_t ctl_f(const arm_pm_design_t *d)
{
    const sys_f_t s = {d->ctl_nx, d->ctl_a, d->ctl_b, d->ctl_c, d->ctl_d};
    return s;
}

PM_INLINE sys_q_t est_q(const arm_pm_design_t *d)
{
    const sys_q_t s = {d->est_nx, d->est_a_q, d->est_b_q, d->est_c_q, d->est_d_q,
                       d->est_acc_x_shift, d->est_acc_u_shift};
    return s;
}

PM_INLINE sys_q_t ctl_q(const arm_pm_design_t *d)
{
    const sys_q_t s = {d->ctl_nx, d->ctl_a_q, d->ctl_b_q, d->ctl_c_q, d->ctl_d_q,
                       d->ctl_acc_x_shift, d->ctl_acc_u_shift};
    return s;
}

/* ---- float32: D first, then C x in state order; B first, then A x (the headers' order) ---- */

PM_INLINE float output_f(const sys_f_t *s, const float *x, const float v[2])
{
    float acc = s->d[0] * v[0] + s->d[1] * v[1];
    for (int i = 0; i < s->nx; ++i) {
        acc += s->c[i] * x[i];
    }
    return acc;
}

PM_INLINE void update_f(const sys_f_t *s, float x[ARM_PM_NX_MAX], const float v[2])
{
    float next[ARM_PM_NX_MAX];
    for (int i = 0; i < s->nx; ++i) {
        float acc = s->b[i * 2] * v[0] + s->b[i * 2 + 1] * v[1];
        for (int j = 0; j < s->nx; ++j) {
            acc += s->a[i * s->nx + j] * x[j];
        }
        next[i] = acc;
    }
    for (int i = 0; i < s->nx; ++i) {
        x[i] = next[i]; /* states past nx stay 0 */
    }
}

PM_INLINE void im_update_f(const arm_pm_design_t *d, float x[2], float u)
{
    const float x0 = d->im_a[0] * x[0] + d->im_a[1] * x[1] + d->im_b[0] * u;
    const float x1 = d->im_a[2] * x[0] + d->im_a[3] * x[1] + d->im_b[1] * u;
    x[0] = x0;
    x[1] = x1;
}

/* ---- fixed point: exactly the arithmetic pm_design_fixed.h prescribes --------------------- */

PM_INLINE int32_t sat32(int64_t v)
{
    return v > 2147483647LL ? 2147483647 : (v < -2147483647LL ? -2147483647 : (int32_t)v);
}

PM_INLINE int32_t round_shift(int64_t acc, int shift)
{
    if (shift == 0) {
        return sat32(acc);
    }
    return sat32((acc + ((int64_t)1 << (shift - 1))) >> shift);
}

PM_INLINE int32_t sat_range(int32_t v, int32_t lim)
{
    return v > lim ? lim : (v < -lim ? -lim : v);
}

PM_INLINE int32_t to_q(float v, int frac, int32_t lim)
{
    /* lrintf would round half to even; the proof only needs |error| <= 1/2 LSB either way. */
    const float scaled = v * (float)(1LL << frac);
    if (!(scaled < 2147483520.0f)) return lim; /* also catches NaN: the safety layer stops first */
    if (!(scaled > -2147483520.0f)) return -lim;
    return sat_range((int32_t)lrintf(scaled), lim);
}

PM_INLINE float from_q(int32_t v, int frac)
{
    return (float)v / (float)(1LL << frac);
}

PM_INLINE int32_t output_q(const sys_q_t *s, const int32_t *x, const int32_t v[2])
{
    int64_t acc = (int64_t)s->d[0] * v[0] + (int64_t)s->d[1] * v[1];
    for (int i = 0; i < s->nx; ++i) {
        acc += (int64_t)s->c[i] * x[i];
    }
    return round_shift(acc, s->acc_u_shift);
}

PM_INLINE void update_q(const sys_q_t *s, int32_t x[ARM_PM_NX_MAX], const int32_t v[2])
{
    int32_t next[ARM_PM_NX_MAX];
    for (int i = 0; i < s->nx; ++i) {
        int64_t acc = (int64_t)s->b[i * 2] * v[0] + (int64_t)s->b[i * 2 + 1] * v[1];
        for (int j = 0; j < s->nx; ++j) {
            acc += (int64_t)s->a[i * s->nx + j] * x[j];
        }
        next[i] = round_shift(acc, s->acc_x_shift);
    }
    for (int i = 0; i < s->nx; ++i) {
        x[i] = next[i];
    }
}

PM_INLINE void im_update_q(const arm_pm_design_t *d, int32_t x[2], int32_t u)
{
    const int64_t a0 = (int64_t)d->im_a_q[0] * x[0] + (int64_t)d->im_a_q[1] * x[1] +
                       (int64_t)d->im_b_q[0] * u;
    const int64_t a1 = (int64_t)d->im_a_q[2] * x[0] + (int64_t)d->im_a_q[3] * x[1] +
                       (int64_t)d->im_b_q[1] * u;
    x[0] = sat_range(round_shift(a0, d->im_acc_x_shift), d->im_e_max_q);
    x[1] = sat_range(round_shift(a1, d->im_acc_x_shift), d->im_e_dot_max_q);
}

/* ---- interface ----------------------------------------------------------------------------- */

void arm_pm_init(arm_pm_t *pm, const arm_pm_design_t *design, arm_numeric_t numeric,
                 arm_pm_structure_t structure)
{
    memset(pm, 0, sizeof(*pm));
    pm->d = design;
    pm->numeric = numeric;
    pm->structure = structure;
}

/* A design's blocks, as inlined into each path (the interface below). */
typedef struct {
    const arm_pm_design_t *d; /* the internal model's tables, the formats */
    sys_f_t ef, cf;
    sys_q_t eq, cq;
} blocks_t;

PM_INLINE void output_float(arm_pm_t *pm, const blocks_t *b, arm_pm_structure_t structure,
                            const float e[ARM_N_JOINTS], const float e_dot[ARM_N_JOINTS], float u_o[ARM_N_JOINTS],
                            float w_hat[ARM_N_JOINTS])
{
    const int with_estimator = structure != ARM_PM_NO_ESTIMATOR;
    const int decoupled = structure == ARM_PM_DECOUPLED;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        float *y = pm->s.f.y[j];
        float *v = pm->s.f.v[j];
        y[0] = e[j];
        y[1] = e_dot[j];
        if (!pm->primed) {
            pm->s.f.im[j][0] = y[0];
            pm->s.f.im[j][1] = y[1];
        }
        pm->s.f.u_o[j] = output_f(&b->cf, pm->s.f.ctl[j], y);
        v[0] = decoupled ? y[0] - pm->s.f.im[j][0] : y[0];
        v[1] = decoupled ? y[1] - pm->s.f.im[j][1] : y[1];
        u_o[j] = pm->s.f.u_o[j];
        w_hat[j] = with_estimator ? output_f(&b->ef, pm->s.f.est[j], v) : 0.0f;
    }
}

PM_INLINE void output_fixed(arm_pm_t *pm, const blocks_t *b, arm_pm_structure_t structure,
                            const float e[ARM_N_JOINTS], const float e_dot[ARM_N_JOINTS], float u_o[ARM_N_JOINTS],
                            float w_hat[ARM_N_JOINTS])
{
    const arm_pm_design_t *d = b->d;
    const int with_estimator = structure != ARM_PM_NO_ESTIMATOR;
    const int decoupled = structure == ARM_PM_DECOUPLED;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        int32_t *y = pm->s.q.y[j];
        int32_t *v = pm->s.q.v[j];
        y[0] = to_q(e[j], d->y_frac, d->range_e_max_q);
        y[1] = to_q(e_dot[j], d->y_frac, d->range_e_dot_max_q);
        if (!pm->primed) {
            pm->s.q.im[j][0] = y[0];
            pm->s.q.im[j][1] = y[1];
        }
        pm->s.q.u_o[j] = output_q(&b->cq, pm->s.q.ctl[j], y);
        v[0] = decoupled ? sat_range(y[0] - pm->s.q.im[j][0], d->range_e_max_q) : y[0];
        v[1] = decoupled ? sat_range(y[1] - pm->s.q.im[j][1], d->range_e_dot_max_q) : y[1];
        u_o[j] = from_q(pm->s.q.u_o[j], d->ctl_u_frac);
        w_hat[j] = with_estimator ? from_q(output_q(&b->eq, pm->s.q.est[j], v), d->est_u_frac)
                                  : 0.0f;
    }
}

PM_INLINE void update_float(arm_pm_t *pm, const blocks_t *b, arm_pm_structure_t structure, uint32_t hold_mask)
{
    const int with_estimator = structure != ARM_PM_NO_ESTIMATOR;
    const int decoupled = structure == ARM_PM_DECOUPLED;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const int hold = (hold_mask >> j) & 1u;
        update_f(&b->cf, pm->s.f.ctl[j], pm->s.f.y[j]);
        if (with_estimator && !hold) {
            update_f(&b->ef, pm->s.f.est[j], pm->s.f.v[j]);
            if (decoupled) im_update_f(b->d, pm->s.f.im[j], pm->s.f.u_o[j]);
        } else if (decoupled && hold) {
            /* Anti-windup: while the limiter decides the torque, K is held and the internal
             * model follows the measured error, so K does not learn the limiter as w. */
            pm->s.f.im[j][0] = pm->s.f.y[j][0];
            pm->s.f.im[j][1] = pm->s.f.y[j][1];
        }
    }
}

PM_INLINE void update_fixed(arm_pm_t *pm, const blocks_t *b, arm_pm_structure_t structure, uint32_t hold_mask)
{
    const int with_estimator = structure != ARM_PM_NO_ESTIMATOR;
    const int decoupled = structure == ARM_PM_DECOUPLED;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const int hold = (hold_mask >> j) & 1u;
        update_q(&b->cq, pm->s.q.ctl[j], pm->s.q.y[j]);
        if (with_estimator && !hold) {
            update_q(&b->eq, pm->s.q.est[j], pm->s.q.v[j]);
            if (decoupled) im_update_q(b->d, pm->s.q.im[j], pm->s.q.u_o[j]);
        } else if (decoupled && hold) {
            pm->s.q.im[j][0] = pm->s.q.y[j][0];
            pm->s.q.im[j][1] = pm->s.q.y[j][1];
        }
    }
}

/* The built-in design's blocks: dimensions and tables from pm_design_*.h, its padding states left
 * out (they stay 0: A = B = C = 0). */
#define BUILTIN_BLOCKS                                                                                  \
    {&arm_pm_builtin_design,                                                                            \
     {ARM_EST_NX - ARM_EST_NX_PADDING, &ARM_EST_A[0][0], &ARM_EST_B[0][0], &ARM_EST_C[0][0], &ARM_EST_D[0][0]}, \
     {ARM_CTL_NX - ARM_CTL_NX_PADDING, &ARM_CTL_A[0][0], &ARM_CTL_B[0][0], &ARM_CTL_C[0][0], &ARM_CTL_D[0][0]}, \
     {ARM_EST_NX - ARM_EST_NX_PADDING, &ARM_EST_A_Q[0][0], &ARM_EST_B_Q[0][0], &ARM_EST_C_Q[0][0],             \
      &ARM_EST_D_Q[0][0], ARM_EST_ACC_X_SHIFT, ARM_EST_ACC_U_SHIFT},                                     \
     {ARM_CTL_NX - ARM_CTL_NX_PADDING, &ARM_CTL_A_Q[0][0], &ARM_CTL_B_Q[0][0], &ARM_CTL_C_Q[0][0],             \
      &ARM_CTL_D_Q[0][0], ARM_CTL_ACC_X_SHIFT, ARM_CTL_ACC_U_SHIFT}}

#if ARM_PM_RUNTIME_DESIGNS
static blocks_t design_blocks(const arm_pm_design_t *d)
{
    const blocks_t b = {d, est_f(d), ctl_f(d), est_q(d), ctl_q(d)};
    return b;
}
#endif

/* The built-in design, with its structure a constant too: each structure's copy has no branch
 * on it. */
#define PM_BUILTIN_CALL(fn, ...)                                                                      \
    do {                                                                                              \
        static const blocks_t builtin = BUILTIN_BLOCKS;                                               \
        switch (pm->structure) {                                                                      \
        case ARM_PM_DECOUPLED: fn(pm, &builtin, ARM_PM_DECOUPLED, __VA_ARGS__); break;                \
        case ARM_PM_PAPER: fn(pm, &builtin, ARM_PM_PAPER, __VA_ARGS__); break;                        \
        case ARM_PM_NO_ESTIMATOR: fn(pm, &builtin, ARM_PM_NO_ESTIMATOR, __VA_ARGS__); break;          \
        }                                                                                             \
    } while (0)

void arm_pm_output(arm_pm_t *pm, const float e[ARM_N_JOINTS], const float e_dot[ARM_N_JOINTS],
                   float u_o[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS])
{
#if ARM_PM_RUNTIME_DESIGNS
    if (pm->d != &arm_pm_builtin_design) {
        const blocks_t b = design_blocks(pm->d);
        if (pm->numeric == ARM_NUMERIC_FLOAT) {
            output_float(pm, &b, pm->structure, e, e_dot, u_o, w_hat);
        } else {
            output_fixed(pm, &b, pm->structure, e, e_dot, u_o, w_hat);
        }
        pm->primed = 1;
        return;
    }
#endif
    if (pm->numeric == ARM_NUMERIC_FLOAT) {
        PM_BUILTIN_CALL(output_float, e, e_dot, u_o, w_hat);
    } else {
        PM_BUILTIN_CALL(output_fixed, e, e_dot, u_o, w_hat);
    }
    pm->primed = 1;
}

void arm_pm_update(arm_pm_t *pm, uint32_t hold_mask)
{
#if ARM_PM_RUNTIME_DESIGNS
    if (pm->d != &arm_pm_builtin_design) {
        const blocks_t b = design_blocks(pm->d);
        if (pm->numeric == ARM_NUMERIC_FLOAT) {
            update_float(pm, &b, pm->structure, hold_mask);
        } else {
            update_fixed(pm, &b, pm->structure, hold_mask);
        }
        return;
    }
#endif
    if (pm->numeric == ARM_NUMERIC_FLOAT) {
        PM_BUILTIN_CALL(update_float, hold_mask);
    } else {
        PM_BUILTIN_CALL(update_fixed, hold_mask);
    }
}

int arm_pm_design_fits(const arm_pm_design_t *d)
{
    if (d == NULL || d->n_joints != ARM_N_JOINTS) return -1;
#if !ARM_PM_RUNTIME_DESIGNS
    if (d != &arm_pm_builtin_design) return -1; /* this build runs its own design alone */
#endif
    if (d->est_nx < 1 || d->est_nx > ARM_PM_EST_NX_MAX || d->ctl_nx < 1 || d->ctl_nx > ARM_PM_CTL_NX_MAX) return -1;
    const void *const tables[] = {d->est_a, d->est_b, d->est_c, d->est_d, d->ctl_a, d->ctl_b, d->ctl_c,
                                  d->ctl_d, d->im_a, d->im_b, d->est_a_q, d->est_b_q, d->est_c_q,
                                  d->est_d_q, d->ctl_a_q, d->ctl_b_q, d->ctl_c_q, d->ctl_d_q,
                                  d->im_a_q, d->im_b_q};
    for (size_t i = 0; i < sizeof(tables) / sizeof(tables[0]); ++i) {
        if (tables[i] == NULL) return -1;
    }
    /* 1LL << f and the rounding term 1 << (shift - 1) are defined for 0..62 */
    const int bits[] = {d->y_frac, d->est_u_frac, d->ctl_u_frac, d->est_acc_x_shift, d->est_acc_u_shift,
                        d->ctl_acc_x_shift, d->ctl_acc_u_shift, d->im_acc_x_shift};
    for (size_t i = 0; i < sizeof(bits) / sizeof(bits[0]); ++i) {
        if (bits[i] < 0 || bits[i] > 62) return -1;
    }
    return d->range_e_max_q > 0 && d->range_e_dot_max_q > 0 && d->im_e_max_q > 0 && d->im_e_dot_max_q > 0 ? 0 : -1;
}

int arm_pm_check_design(const arm_pm_design_t *d, float loop_rate_hz)
{
    return fabsf(loop_rate_hz - d->loop_rate_hz) <= 1e-3f * d->loop_rate_hz ? 0 : -1;
}

/* The built-in design: the generated tables themselves (no copy), read through the struct. */
const arm_pm_design_t arm_pm_builtin_design = {
    .hash = ARM_DESIGN_HASH,
    .n_joints = ARM_DESIGN_N_JOINTS,
    .loop_rate_hz = (float)ARM_LOOP_RATE_HZ,
    .est_nx = ARM_EST_NX,
    .ctl_nx = ARM_CTL_NX,
    .est_a = &ARM_EST_A[0][0], .est_b = &ARM_EST_B[0][0], .est_c = &ARM_EST_C[0][0], .est_d = &ARM_EST_D[0][0],
    .ctl_a = &ARM_CTL_A[0][0], .ctl_b = &ARM_CTL_B[0][0], .ctl_c = &ARM_CTL_C[0][0], .ctl_d = &ARM_CTL_D[0][0],
    .im_a = &ARM_IM_A[0][0], .im_b = &ARM_IM_B[0][0],
    .est_a_q = &ARM_EST_A_Q[0][0], .est_b_q = &ARM_EST_B_Q[0][0], .est_c_q = &ARM_EST_C_Q[0][0],
    .est_d_q = &ARM_EST_D_Q[0][0],
    .ctl_a_q = &ARM_CTL_A_Q[0][0], .ctl_b_q = &ARM_CTL_B_Q[0][0], .ctl_c_q = &ARM_CTL_C_Q[0][0],
    .ctl_d_q = &ARM_CTL_D_Q[0][0],
    .im_a_q = &ARM_IM_A_Q[0][0], .im_b_q = &ARM_IM_B_Q[0][0],
    .y_frac = ARM_Y_FRAC,
    .est_u_frac = ARM_EST_U_FRAC,
    .ctl_u_frac = ARM_CTL_U_FRAC,
    .est_acc_x_shift = ARM_EST_ACC_X_SHIFT,
    .est_acc_u_shift = ARM_EST_ACC_U_SHIFT,
    .ctl_acc_x_shift = ARM_CTL_ACC_X_SHIFT,
    .ctl_acc_u_shift = ARM_CTL_ACC_U_SHIFT,
    .im_acc_x_shift = ARM_IM_ACC_X_SHIFT,
    .range_e_max_q = ARM_RANGE_E_MAX_Q,
    .range_e_dot_max_q = ARM_RANGE_E_DOT_MAX_Q,
    .im_e_max_q = ARM_IM_E_MAX_Q,
    .im_e_dot_max_q = ARM_IM_E_DOT_MAX_Q,
};
