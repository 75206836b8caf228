/* The method table: every method the control step runs, in arm_method_t order. */
#include "arm/methods.h"

#include <stddef.h>

static void pd_output(arm_ctl_t *ctl, arm_ctl_output_t *out)
{
    const arm_ctl_config_t *c = &ctl->cfg;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        out->u_o[i] = -c->kp * out->e[i] - c->kd * out->e_dot[i];
        out->w_hat[i] = 0.0f;
    }
}

static void no_state(arm_ctl_t *ctl)
{
    (void)ctl;
}

static void no_update(arm_ctl_t *ctl, const float acc[ARM_N_JOINTS], uint32_t hold_mask)
{
    (void)ctl;
    (void)acc;
    (void)hold_mask;
}

static void pm_init(arm_ctl_t *ctl) { arm_pm_init(&ctl->m.pm, ctl->cfg.design, ctl->cfg.numeric, ARM_PM_DECOUPLED); }
static void pm_paper_init(arm_ctl_t *ctl) { arm_pm_init(&ctl->m.pm, ctl->cfg.design, ctl->cfg.numeric, ARM_PM_PAPER); }
static void gh2_init(arm_ctl_t *ctl) { arm_pm_init(&ctl->m.pm, ctl->cfg.design, ctl->cfg.numeric, ARM_PM_NO_ESTIMATOR); }

static void pm_output(arm_ctl_t *ctl, arm_ctl_output_t *out)
{
    arm_pm_output(&ctl->m.pm, out->e, out->e_dot, out->u_o, out->w_hat);
}

static void pm_update(arm_ctl_t *ctl, const float acc[ARM_N_JOINTS], uint32_t hold_mask)
{
    (void)acc;
    arm_pm_update(&ctl->m.pm, hold_mask);
}

static void tde_init(arm_ctl_t *ctl) { arm_tde_init(&ctl->m.tde, ctl->cfg.period_s, ctl->cfg.tde_cutoff_hz); }

static void tde_output(arm_ctl_t *ctl, arm_ctl_output_t *out)
{
    pd_output(ctl, out);
    arm_tde_output(&ctl->m.tde, ctl->last_qd, out->w_hat);
}

static void tde_update(arm_ctl_t *ctl, const float acc[ARM_N_JOINTS], uint32_t hold_mask)
{
    arm_tde_update(&ctl->m.tde, ctl->last_qd, acc, hold_mask);
}

static void usde_smc_init(arm_ctl_t *ctl)
{
    const arm_ctl_config_t *c = &ctl->cfg;
    arm_usde_smc_init(&ctl->m.usde_smc, c->period_s, c->usde_k, c->smc_lambda, c->smc_eta, c->smc_phi, c->smc_ks);
}

static void usde_smc_output(arm_ctl_t *ctl, arm_ctl_output_t *out)
{
    arm_usde_smc_output(&ctl->m.usde_smc, out->e, out->e_dot, ctl->last_qd, out->u_o, out->w_hat);
}

static void usde_smc_update(arm_ctl_t *ctl, const float acc[ARM_N_JOINTS], uint32_t hold_mask)
{
    arm_usde_smc_update(&ctl->m.usde_smc, ctl->last_qd, acc, hold_mask);
}

/* The table: X(index, name, uses the design, init, output, update), one line a method. */
#define ARM_METHOD_TABLE(X)                                                      \
    X(ARM_METHOD_PD, "pd", 0, no_state, pd_output, no_update)                    \
    X(ARM_METHOD_PM, "pm", 1, pm_init, pm_output, pm_update)                     \
    X(ARM_METHOD_PM_PAPER, "pm-paper", 1, pm_paper_init, pm_output, pm_update)   \
    X(ARM_METHOD_GH2, "gh2", 1, gh2_init, pm_output, pm_update)                  \
    X(ARM_METHOD_TDE, "tde", 0, tde_init, tde_output, tde_update)                \
    X(ARM_METHOD_USDE_SMC, "usde-smc", 0, usde_smc_init, usde_smc_output, usde_smc_update)

#define OPS(id, name, design, init, output, update) [id] = {name, design},
static const arm_method_ops_t k_methods[ARM_METHOD_COUNT] = {ARM_METHOD_TABLE(OPS)};
#undef OPS

const arm_method_ops_t *arm_method_ops(arm_method_t m)
{
    return (unsigned)m < (unsigned)ARM_METHOD_COUNT ? &k_methods[m] : NULL;
}

void arm_method_init(arm_ctl_t *ctl)
{
#define INIT(id, name, design, init, output, update) case id: init(ctl); break;
    switch (ctl->cfg.method) {
        ARM_METHOD_TABLE(INIT)
    case ARM_METHOD_COUNT: break;
    }
#undef INIT
}

void arm_method_output(arm_ctl_t *ctl, arm_ctl_output_t *out)
{
#define OUTPUT(id, name, design, init, output, update) case id: output(ctl, out); break;
    switch (ctl->cfg.method) {
        ARM_METHOD_TABLE(OUTPUT)
    case ARM_METHOD_COUNT: break;
    }
#undef OUTPUT
}

void arm_method_update(arm_ctl_t *ctl, const float acc[ARM_N_JOINTS], uint32_t hold_mask)
{
#define UPDATE(id, name, design, init, output, update) case id: update(ctl, acc, hold_mask); break;
    switch (ctl->cfg.method) {
        ARM_METHOD_TABLE(UPDATE)
    case ARM_METHOD_COUNT: break;
    }
#undef UPDATE
}
