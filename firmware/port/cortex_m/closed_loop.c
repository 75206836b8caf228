#include "closed_loop.h"

#include <math.h>
#include <string.h>

#include "arm/reference.h"
#include "arm/rnea.h"

int cl_cases(cl_case_t cases[CL_MAX_CASES])
{
    int n = 0;
    for (int m = 0; m < (int)ARM_METHOD_COUNT && n < CL_MAX_CASES; ++m) {
        cases[n].method = (arm_method_t)m;
        cases[n].numeric = ARM_NUMERIC_FLOAT;
        ++n;
    }
    const arm_method_t fixed[] = {ARM_METHOD_PM, ARM_METHOD_PM_PAPER, ARM_METHOD_GH2};
    for (unsigned i = 0; i < sizeof(fixed) / sizeof(fixed[0]) && n < CL_MAX_CASES; ++i) {
        cases[n].method = fixed[i];
        cases[n].numeric = ARM_NUMERIC_FIXED;
        ++n;
    }
    return n;
}

/* qdd = M(q)^-1 (tau - h(q, qd)), M from unit-acceleration RNEA calls, solved by Cholesky. */
static void forward_dynamics(const arm_robot_model_t *model, const float q[ARM_N_JOINTS],
                             const float qd[ARM_N_JOINTS], const float tau[ARM_N_JOINTS],
                             float qdd[ARM_N_JOINTS])
{
    static const float zero[ARM_N_JOINTS];
    float m[ARM_N_JOINTS][ARM_N_JOINTS];
    float g[ARM_N_JOINTS], h[ARM_N_JOINTS], col[ARM_N_JOINTS], e[ARM_N_JOINTS];
    arm_rnea(model, q, zero, zero, g);
    arm_rnea(model, q, qd, zero, h);
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        memset(e, 0, sizeof(e));
        e[j] = 1.0f;
        arm_rnea(model, q, zero, e, col);
        for (int i = 0; i < ARM_N_JOINTS; ++i) {
            m[i][j] = col[i] - g[i];
        }
    }
    float l[ARM_N_JOINTS][ARM_N_JOINTS];
    memset(l, 0, sizeof(l));
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        for (int j = 0; j <= i; ++j) {
            float s = 0.5f * (m[i][j] + m[j][i]);
            for (int k = 0; k < j; ++k) {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = i == j ? sqrtf(s > 1e-9f ? s : 1e-9f) : s / l[j][j];
        }
    }
    float y[ARM_N_JOINTS];
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        float s = tau[i] - h[i];
        for (int k = 0; k < i; ++k) {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    for (int i = ARM_N_JOINTS - 1; i >= 0; --i) {
        float s = y[i];
        for (int k = i + 1; k < ARM_N_JOINTS; ++k) {
            s -= l[k][i] * qdd[k];
        }
        qdd[i] = s / l[i][i];
    }
}

void cl_run(const arm_robot_model_t *model, const float home[ARM_N_JOINTS], const cl_case_t *c, cl_result_t *r)
{
    static arm_ctl_t ctl; /* large (method states): static, like the ports */
    memset(r, 0, sizeof(*r));
    arm_ctl_config_t cfg;
    arm_ctl_default_config(model, &cfg);
    cfg.method = c->method;
    cfg.numeric = c->numeric;
    r->init_result = (int)arm_ctl_init(&ctl, model, &cfg);
    if (r->init_result != 0) {
        return;
    }
    float q[ARM_N_JOINTS], qd[ARM_N_JOINTS];
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        q[j] = home[j];
        qd[j] = 0.0f;
    }
    arm_reference_t ref;
    arm_reference_default(&ref, q);
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    memset(&in, 0, sizeof(in));
    const float dt = cfg.period_s;
    for (uint32_t k = 0; k < CL_STEPS; ++k) {
        const float t = (float)k * dt;
        memcpy(in.q, q, sizeof(q));
        memcpy(in.qd, qd, sizeof(qd));
        in.fresh_mask = (uint32_t)((1ull << ARM_N_JOINTS) - 1u);
        arm_reference_eval(&ref, t, in.q_d, in.qd_d, in.qdd_d);
        arm_ctl_step(&ctl, &in, &out);
        memcpy(in.tau_measured, out.tau, sizeof(in.tau_measured)); /* the drives do as told */
        if (k % CL_RECORD_EVERY == 0u) {
            memcpy(r->tau[k / CL_RECORD_EVERY], out.tau, sizeof(out.tau));
        }
        float qdd[ARM_N_JOINTS];
        forward_dynamics(model, q, qd, out.tau, qdd);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            /* The paper's matched disturbance w (e_ddot = u + w): 2 rad/s^2, smooth, from zero. */
            qdd[j] += 2.0f * sinf(6.2831853f * (1.0f + 0.25f * (float)j) * t);
            qd[j] += qdd[j] * dt;
            q[j] += qd[j] * dt;
        }
    }
    memcpy(r->q_final, q, sizeof(q));
    r->final_state = (uint32_t)out.state;
}
