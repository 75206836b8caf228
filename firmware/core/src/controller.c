#include "arm/controller.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "arm/methods.h"
#include "arm_params.h"
#include "arm/rnea.h"
#include "arm_rnea_kernel.h"

#define ARM_ALL_JOINTS_MASK ((uint32_t)((1ull << ARM_N_JOINTS) - 1u))
_Static_assert((ARM_TORQUE_REPORT_LAG_MAX & (ARM_TORQUE_REPORT_LAG_MAX - 1u)) == 0u, "a power of two: the ring's index");

void arm_ctl_joint_range(const arm_robot_model_t *model, float margin, float q_min[ARM_N_JOINTS],
                         float q_max[ARM_N_JOINTS])
{
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const arm_link_t *l = &model->link[i];
        q_min[i] = l->q_min > -ARM_UNLIMITED ? l->q_min - margin : -ARM_UNLIMITED;
        q_max[i] = l->q_max < ARM_UNLIMITED ? l->q_max + margin : ARM_UNLIMITED;
    }
}

/* The defaults are the registry's (firmware/params/params.toml, as arm_params.h): arm_controller's
 * options document and parse the same numbers. */
void arm_ctl_default_config(const arm_robot_model_t *model, arm_ctl_config_t *cfg)
{
    memset(cfg, 0, sizeof(*cfg));
    cfg->method = ARM_METHOD_PD;
    cfg->period_s = (float)(1.0 / ARM_P_CONTROLLER_RATE_DEFAULT);
    /* wn = 20 rad/s: well below the 1 kHz loop, above the reference's content */
    cfg->kp = (float)ARM_P_CONTROLLER_KP_DEFAULT;
    cfg->kd = (float)ARM_P_CONTROLLER_KD_DEFAULT;
    cfg->numeric = ARM_NUMERIC_FLOAT;
    cfg->design = &arm_pm_builtin_design;
    cfg->tde_cutoff_hz = (float)ARM_P_CONTROLLER_TDE_CUTOFF_DEFAULT;
    cfg->usde_k = (float)ARM_P_CONTROLLER_USDE_K_DEFAULT;
    cfg->smc_lambda = (float)ARM_P_CONTROLLER_SMC_LAMBDA_DEFAULT;
    cfg->smc_eta = (float)ARM_P_CONTROLLER_SMC_ETA_DEFAULT;
    cfg->smc_phi = (float)ARM_P_CONTROLLER_SMC_PHI_DEFAULT;
    cfg->smc_ks = (float)ARM_P_CONTROLLER_SMC_KS_DEFAULT;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        cfg->torque_limit[i] = model->link[i].torque_limit;
        /* Full scale in 10 ms: fast enough to take the arm's weight within a few periods of
         * enabling, slow enough to turn a corrupted command into a ramp rather than a jump. */
        cfg->torque_rate_limit[i] = model->link[i].torque_limit * (cfg->period_s / 0.010f);
    }
    cfg->watchdog_periods = ARM_P_CONTROLLER_WATCHDOG_PERIODS_DEFAULT;
    cfg->safe_stop_rate = (float)ARM_P_SAFE_STOP_HOLD_RATE;
    cfg->checks = ARM_CHECK_ALL;
    /* A noisy encoder, a filtered velocity and a lagging current loop stay far inside these; a
     * corrupted or spoofed state, a runaway joint or a drive that does not do as told do not. */
    cfg->step_tolerance = (float)ARM_P_CONTROLLER_STEP_TOLERANCE_DEFAULT;
    cfg->torque_mismatch_periods = 3u;
    cfg->torque_report_lag_min = 1u;
    cfg->torque_report_lag_max = 1u;
    arm_ctl_joint_range(model, (float)ARM_P_CONTROLLER_POSITION_MARGIN_DEFAULT, cfg->q_min, cfg->q_max);
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        cfg->velocity_limit[i] = (float)ARM_P_CONTROLLER_MAX_VELOCITY_DEFAULT;
        cfg->following_error_limit[i] = (float)ARM_P_CONTROLLER_MAX_FOLLOWING_ERROR_DEFAULT;
        cfg->torque_mismatch_limit[i] = (float)ARM_P_CONTROLLER_TORQUE_MISMATCH_DEFAULT * model->link[i].torque_limit;
    }
}

arm_ctl_init_result_t arm_ctl_init(arm_ctl_t *ctl, const arm_robot_model_t *model,
                                   const arm_ctl_config_t *cfg)
{
    const arm_method_ops_t *ops = arm_method_ops(cfg->method);
    if (ops == NULL) {
        return ARM_CTL_BAD_METHOD;
    }
    if (!(cfg->period_s > 0.0f && cfg->period_s < 1.0f)) {
        return ARM_CTL_BAD_PERIOD;
    }
    if (!(isfinite(cfg->kp) && isfinite(cfg->kd) && cfg->kp >= 0.0f && cfg->kd >= 0.0f &&
          isfinite(cfg->safe_stop_rate) && cfg->safe_stop_rate >= 0.0f)) {
        return ARM_CTL_BAD_GAIN;
    }
    if ((unsigned)cfg->numeric > (unsigned)ARM_NUMERIC_FIXED) {
        return ARM_CTL_BAD_NUMERIC;
    }
    if (!(cfg->tde_cutoff_hz > 0.0f && cfg->usde_k > 0.0f && cfg->smc_lambda >= 0.0f &&
          cfg->smc_eta >= 0.0f && cfg->smc_phi > 0.0f && cfg->smc_ks >= 0.0f &&
          isfinite(cfg->tde_cutoff_hz) && isfinite(cfg->usde_k) && isfinite(cfg->smc_lambda) &&
          isfinite(cfg->smc_eta) && isfinite(cfg->smc_phi) && isfinite(cfg->smc_ks))) {
        return ARM_CTL_BAD_GAIN;
    }
    if (ops->uses_design && arm_pm_design_fits(cfg->design) != 0) {
        return ARM_CTL_BAD_DESIGN;
    }
    if (ops->uses_design && arm_pm_check_design(cfg->design, 1.0f / cfg->period_s) != 0) {
        return ARM_CTL_BAD_DESIGN_RATE;
    }
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        if (!(cfg->torque_limit[i] > 0.0f && isfinite(cfg->torque_limit[i]) &&
              cfg->torque_rate_limit[i] > 0.0f && isfinite(cfg->torque_rate_limit[i]))) {
            return ARM_CTL_BAD_LIMIT;
        }
        if (!(cfg->q_min[i] < cfg->q_max[i])) return ARM_CTL_BAD_RANGE;
        if (!(cfg->velocity_limit[i] > 0.0f)) return ARM_CTL_BAD_VELOCITY_LIMIT;
        if (!(cfg->following_error_limit[i] > 0.0f)) return ARM_CTL_BAD_FOLLOWING_LIMIT;
        if (!(cfg->torque_mismatch_limit[i] > 0.0f)) return ARM_CTL_BAD_MISMATCH_LIMIT;
    }
    if (cfg->torque_mismatch_periods < 1u || cfg->torque_report_lag_min < 1u ||
        cfg->torque_report_lag_max < cfg->torque_report_lag_min ||
        cfg->torque_report_lag_max > ARM_TORQUE_REPORT_LAG_MAX) {
        return ARM_CTL_BAD_MISMATCH_LIMIT;
    }
    if (!(cfg->step_tolerance > 0.0f)) return ARM_CTL_BAD_STEP_TOLERANCE;
    memset(ctl, 0, sizeof(*ctl));
    ctl->model = model;
    ctl->rnea_kernel = arm_rnea_kernel_fits(model);
    ctl->cfg = *cfg;
    ctl->state = ARM_STATE_INIT;
    ctl->fault = ARM_FAULT_NONE;
    ctl->fault_joint = -1;
    arm_method_init(ctl);
    return ARM_CTL_OK;
}

/* x - x is +0 for every finite x and NaN for an infinity or a NaN, and a NaN stays NaN through any
 * sum: one subtraction and one addition per value, no branch (isfinite per value branches). */
static int all_finite(const float *v, int n)
{
    float z = 0.0f;
    for (int i = 0; i < n; ++i) {
        z += v[i] - v[i];
    }
    return z == 0.0f;
}

static int input_finite(const arm_ctl_input_t *in)
{
    float z = 0.0f; /* all_finite's sum, over the five inputs in one pass */
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        z += ((in->q[i] - in->q[i]) + (in->qd[i] - in->qd[i])) +
             ((in->q_d[i] - in->q_d[i]) + (in->qd_d[i] - in->qd_d[i])) + (in->qdd_d[i] - in->qdd_d[i]);
    }
    return z == 0.0f;
}

static void latch_fault(arm_ctl_t *ctl, arm_fault_t fault)
{
    if (ctl->state != ARM_STATE_SAFE_STOP && ctl->state != ARM_STATE_FAULT) {
        ctl->state = ARM_STATE_FAULT;
        ctl->fault = fault;
    }
}

void arm_ctl_external_fault(arm_ctl_t *ctl)
{
    latch_fault(ctl, ARM_FAULT_EXTERNAL);
}

void arm_ctl_stop(arm_ctl_t *ctl)
{
    if (ctl->state != ARM_STATE_FAULT) ctl->state = ARM_STATE_SAFE_STOP;
}

static void latch_joint_fault(arm_ctl_t *ctl, arm_fault_t fault, int joint, float value)
{
    if (ctl->state != ARM_STATE_SAFE_STOP && ctl->state != ARM_STATE_FAULT) {
        ctl->fault_joint = joint; /* the first fault is the one reported */
        ctl->fault_value = value;
    }
    latch_fault(ctl, fault);
}

/* Whether the torque reported for joint i is near one of the commands it may be reporting. */
static int torque_near(const arm_ctl_t *ctl, const arm_ctl_input_t *in, int i)
{
    const arm_ctl_config_t *c = &ctl->cfg;
    int near = 0;
    for (uint32_t k = c->torque_report_lag_min; k <= c->torque_report_lag_max && k <= ctl->n_sent; ++k) {
        const float sent = ctl->tau_sent[(ctl->sent_head + k - 1u) % ARM_TORQUE_REPORT_LAG_MAX][i];
        near |= fabsf(in->tau_measured[i] - sent) <= c->torque_mismatch_limit[i];
    }
    return near;
}

/* Every check of plausible() passes for every joint, with no mismatch to count: the common
 * period, decided without a branch per check and joint (the checks' arithmetic is plausible()'s). */
static int all_plausible(const arm_ctl_t *ctl, const arm_ctl_input_t *in, int torque)
{
    const arm_ctl_config_t *c = &ctl->cfg;
    const int range = (c->checks & ARM_CHECK_POSITION_RANGE) != 0u;
    const int velocity = (c->checks & ARM_CHECK_VELOCITY) != 0u;
    const int step = (c->checks & ARM_CHECK_POSITION_STEP) != 0u && ctl->have_last;
    int bad = 0;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float q = in->q[i], qd = in->qd[i];
        const float explained = 0.5f * (qd + ctl->last_qd[i]) * c->period_s;
        bad |= (range & ((q < c->q_min[i]) | (q > c->q_max[i]))) | (velocity & (fabsf(qd) > c->velocity_limit[i])) |
               (step & (fabsf((q - ctl->last_q[i]) - explained) > c->step_tolerance));
    }
    uint32_t near = torque ? 0u : ARM_ALL_JOINTS_MASK; /* torque_near's test, command by command */
    for (uint32_t k = c->torque_report_lag_min; torque && k <= c->torque_report_lag_max && k <= ctl->n_sent; ++k) {
        const float *sent = ctl->tau_sent[(ctl->sent_head + k - 1u) % ARM_TORQUE_REPORT_LAG_MAX];
        for (int i = 0; i < ARM_N_JOINTS; ++i) {
            near |= (uint32_t)(fabsf(in->tau_measured[i] - sent[i]) <= c->torque_mismatch_limit[i]) << i;
        }
    }
    return !bad && near == ARM_ALL_JOINTS_MASK;
}

/* The joint states of this period against the joint's range, its velocity limit and the last
 * period's state (a step the velocities cannot explain), and the torque the drives report
 * against the one commanded last period. Returns 0 when plausible, else latches the fault. */
static int plausible(arm_ctl_t *ctl, const arm_ctl_input_t *in)
{
    const arm_ctl_config_t *c = &ctl->cfg;
    const int torque = (c->checks & ARM_CHECK_TORQUE) && ctl->state == ARM_STATE_RUNNING &&
                       ctl->n_sent >= c->torque_report_lag_min;
    if (all_plausible(ctl, in, torque)) {
        if (torque) memset(ctl->mismatch_periods, 0, sizeof(ctl->mismatch_periods));
        return 1;
    }
    /* something to latch or count: joint by joint, in the checks' order */
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float q = in->q[i], qd = in->qd[i];
        if ((c->checks & ARM_CHECK_POSITION_RANGE) && (q < c->q_min[i] || q > c->q_max[i])) {
            latch_joint_fault(ctl, ARM_FAULT_POSITION_RANGE, i, q);
            return 0;
        }
        if ((c->checks & ARM_CHECK_VELOCITY) && fabsf(qd) > c->velocity_limit[i]) {
            latch_joint_fault(ctl, ARM_FAULT_VELOCITY_LIMIT, i, qd);
            return 0;
        }
        if ((c->checks & ARM_CHECK_POSITION_STEP) && ctl->have_last) {
            const float step = q - ctl->last_q[i];
            const float explained = 0.5f * (qd + ctl->last_qd[i]) * c->period_s;
            if (fabsf(step - explained) > c->step_tolerance) {
                latch_joint_fault(ctl, ARM_FAULT_POSITION_STEP, i, step);
                return 0;
            }
        }
        if (torque) {
            if (!torque_near(ctl, in, i)) {
                if (++ctl->mismatch_periods[i] >= c->torque_mismatch_periods) {
                    latch_joint_fault(ctl, ARM_FAULT_TORQUE_MISMATCH, i, in->tau_measured[i]);
                    return 0;
                }
            } else {
                ctl->mismatch_periods[i] = 0u;
            }
        }
    }
    return 1;
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

/* The safe stop's hold: the model's torque at the arm's pose for a deceleration of the rate times
 * each joint's velocity (gravity compensation plus damping), through the torque and rate limits.
 * The pose and velocity are this period's if they pass the plausibility checks, else the last
 * good pose at rest (gravity alone): a spoofed or stale state never drives the hold. Never zero
 * torque alone: a loaded arm stays where it is while the drives quick-stop and brake. */
static void safe_stop_output(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out)
{
    const int fresh = (in->fresh_mask & ARM_ALL_JOINTS_MASK) == ARM_ALL_JOINTS_MASK && input_finite(in) &&
                      all_plausible(ctl, in, 0);
    if (fresh) {
        memcpy(ctl->last_q, in->q, sizeof(ctl->last_q));
        memcpy(ctl->last_qd, in->qd, sizeof(ctl->last_qd));
        ctl->have_last = 1;
    } else {
        ctl->have_last = 0;
    }
    float rest[ARM_N_JOINTS], acc[ARM_N_JOINTS];
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        rest[i] = 0.0f;
        acc[i] = fresh ? -ctl->cfg.safe_stop_rate * ctl->last_qd[i] : 0.0f;
    }
    float hold[ARM_N_JOINTS];
    if (ctl->rnea_kernel) {
        arm_rnea_kernel(ctl->last_q, rest, acc, hold);
    } else {
        arm_rnea(ctl->model, ctl->last_q, rest, acc, hold);
    }
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float lim = ctl->cfg.torque_limit[i];
        const float rate = ctl->cfg.torque_rate_limit[i];
        const float want = isfinite(hold[i]) ? hold[i] : ctl->tau_prev[i];
        out->tau[i] = clampf(clampf(want, ctl->tau_prev[i] - rate, ctl->tau_prev[i] + rate), -lim, lim);
    }
}

static void run_method(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out,
                       float acc[ARM_N_JOINTS])
{
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        out->e[i] = in->q_d[i] - ctl->last_q[i];
        out->e_dot[i] = in->qd_d[i] - ctl->last_qd[i];
    }
    arm_method_output(ctl, out);
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        /* IDC: commanding q_ddot_d - u makes the nominal error dynamics e_ddot = u (+ w). */
        acc[i] = in->qdd_d[i] - (out->u_o[i] - out->w_hat[i]);
    }
    if (ctl->rnea_kernel) {
        arm_rnea_kernel(ctl->last_q, ctl->last_qd, acc, out->tau_method);
    } else {
        arm_rnea(ctl->model, ctl->last_q, ctl->last_qd, acc, out->tau_method);
    }
    for (int i = 0; i < ARM_N_JOINTS && in->torque_override_mask != 0u; ++i) {
        if ((in->torque_override_mask & (1u << i)) != 0u) out->tau_method[i] = in->tau_override[i];
    }
}

static void apply_limits(arm_ctl_t *ctl, arm_ctl_output_t *out)
{
    out->saturated_mask = 0u;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float lim = ctl->cfg.torque_limit[i];
        const float rate = ctl->cfg.torque_rate_limit[i];
        const float want = out->tau_method[i];
        float tau = clampf(want, ctl->tau_prev[i] - rate, ctl->tau_prev[i] + rate);
        tau = clampf(tau, -lim, lim);
        if (tau != want) {
            out->saturated_mask |= 1u << i;
        }
        out->tau[i] = tau;
    }
}

void arm_ctl_step(arm_ctl_t *ctl, const arm_ctl_input_t *in, arm_ctl_output_t *out)
{
    memset(out, 0, sizeof(*out));
    const int all_fresh = (in->fresh_mask & ARM_ALL_JOINTS_MASK) == ARM_ALL_JOINTS_MASK;

    if (ctl->state == ARM_STATE_INIT || ctl->state == ARM_STATE_RUNNING) {
        if (!input_finite(in)) {
            latch_fault(ctl, ARM_FAULT_NONFINITE_INPUT);
        } else if (all_fresh) {
            if (plausible(ctl, in)) {
                memcpy(ctl->last_q, in->q, sizeof(ctl->last_q));
                memcpy(ctl->last_qd, in->qd, sizeof(ctl->last_qd));
                ctl->have_last = 1;
                ctl->stale_periods = 0u;
                ctl->state = ARM_STATE_RUNNING;
            }
        } else {
            ctl->have_last = 0; /* a missing period: no step to check against */
            if (ctl->state == ARM_STATE_RUNNING && ++ctl->stale_periods > ctl->cfg.watchdog_periods) {
                latch_fault(ctl, ARM_FAULT_STALE_INPUT);
            }
        }
    }

    if (ctl->state == ARM_STATE_RUNNING) {
        /* Stale periods within the watchdog reuse the last state: the hold is bounded. */
        float acc[ARM_N_JOINTS];
        run_method(ctl, in, out, acc);
        int following = -1;
        for (int i = 0; i < ARM_N_JOINTS && (ctl->cfg.checks & ARM_CHECK_FOLLOWING_ERROR); ++i) {
            if (fabsf(out->e[i]) > ctl->cfg.following_error_limit[i]) {
                following = i;
                break;
            }
        }
        if (!all_finite(out->tau_method, ARM_N_JOINTS)) {
            latch_fault(ctl, ARM_FAULT_NONFINITE_OUTPUT);
        } else if (following >= 0) {
            latch_joint_fault(ctl, ARM_FAULT_FOLLOWING_ERROR, following, out->e[following]);
        } else {
            apply_limits(ctl, out);
            arm_method_update(ctl, acc, out->saturated_mask);
        }
    }

    if (ctl->state == ARM_STATE_FAULT || ctl->state == ARM_STATE_SAFE_STOP) {
        safe_stop_output(ctl, in, out);
    }
    /* INIT commands zero torque: out->tau is already zero. */

    memcpy(ctl->tau_prev, out->tau, sizeof(ctl->tau_prev));
    ctl->sent_head = (ctl->sent_head + ARM_TORQUE_REPORT_LAG_MAX - 1u) % ARM_TORQUE_REPORT_LAG_MAX;
    memcpy(ctl->tau_sent[ctl->sent_head], out->tau, sizeof(ctl->tau_sent[0]));
    if (ctl->n_sent < ARM_TORQUE_REPORT_LAG_MAX) ctl->n_sent++;
    out->state = ctl->state;
    out->fault = ctl->fault;
    out->fault_joint = ctl->fault_joint;
    out->fault_value = ctl->fault_value;
    if (ctl->state == ARM_STATE_FAULT) {
        ctl->state = ARM_STATE_SAFE_STOP; /* FAULT is reported for exactly one period */
    }
}

const char *arm_state_str(arm_state_t s)
{
    static const char *const k_names[] = {ARM_P_CONTROLLER_STATES_NAMES};
    return (unsigned)s < sizeof(k_names) / sizeof(k_names[0]) ? k_names[s] : "?";
}

const char *arm_fault_str(arm_fault_t f)
{
    switch (f) {
    case ARM_FAULT_NONE: return "none";
    case ARM_FAULT_NONFINITE_INPUT: return "non-finite input";
    case ARM_FAULT_NONFINITE_OUTPUT: return "non-finite output";
    case ARM_FAULT_STALE_INPUT: return "stale joint state (watchdog)";
    case ARM_FAULT_EXTERNAL: return "external fault reported by the port";
    case ARM_FAULT_POSITION_RANGE: return "joint position outside its range";
    case ARM_FAULT_VELOCITY_LIMIT: return "joint velocity above its limit";
    case ARM_FAULT_POSITION_STEP: return "joint position step the velocities do not explain";
    case ARM_FAULT_FOLLOWING_ERROR: return "following error above its limit";
    case ARM_FAULT_TORQUE_MISMATCH: return "drive reports another torque than commanded";
    }
    return "?";
}

const char *arm_method_str(arm_method_t m)
{
    const arm_method_ops_t *ops = arm_method_ops(m);
    return ops != NULL ? ops->name : "?";
}

arm_method_t arm_method_from_str(const char *name)
{
    for (int i = 0; i < (int)ARM_METHOD_COUNT; ++i) {
        if (strcmp(name, arm_method_ops((arm_method_t)i)->name) == 0) {
            return (arm_method_t)i;
        }
    }
    return ARM_METHOD_COUNT;
}

const char *arm_ctl_init_result_str(arm_ctl_init_result_t r)
{
    switch (r) {
    case ARM_CTL_OK: return "ok";
    case ARM_CTL_BAD_METHOD: return "unknown method";
    case ARM_CTL_BAD_PERIOD: return "period_s must be in (0, 1)";
    case ARM_CTL_BAD_GAIN: return "gains must be finite and >= 0";
    case ARM_CTL_BAD_LIMIT: return "torque and torque-rate limits must be finite and > 0";
    case ARM_CTL_BAD_DESIGN_RATE:
        return "the loop rate differs from the rate the design was discretised for "
               "(pm_design_float.h ARM_LOOP_RATE_HZ): re-run armctl synth for this rate";
    case ARM_CTL_BAD_DESIGN:
        return "the design does not fit this firmware (joint count, state dimensions or formats)";
    case ARM_CTL_BAD_NUMERIC: return "numeric must be float or fixed";
    case ARM_CTL_BAD_RANGE: return "each joint's range must have q_min < q_max";
    case ARM_CTL_BAD_VELOCITY_LIMIT: return "velocity limits must be > 0";
    case ARM_CTL_BAD_FOLLOWING_LIMIT: return "following-error limits must be > 0";
    case ARM_CTL_BAD_MISMATCH_LIMIT: return "torque-mismatch limits must be > 0 and their periods >= 1";
    case ARM_CTL_BAD_STEP_TOLERANCE: return "the step tolerance must be > 0";
    }
    return "?";
}
