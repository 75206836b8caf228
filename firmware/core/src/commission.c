#include "arm/commission.h"

#include <math.h>
#include <string.h>

#define DEG (3.14159265f / 180.0f)

enum { STEP_SETTLE0, STEP_PULSE_POS, STEP_SETTLE1, STEP_SWEEP, STEP_SETTLE2, STEP_PULSE_NEG, STEP_SETTLE3, STEPS };

void arm_commission_default_config(arm_cm_config_t *cfg)
{
    memset(cfg, 0, sizeof(*cfg));
    cfg->bound_rad = 2.0f * DEG;
    cfg->trip_rad = 0.75f * DEG;
    cfg->pulse_max_s = 0.4f;
    cfg->settle_s = 0.4f;
    cfg->first_settle_s = 1.0f;
    cfg->hold_window_s = 0.15f;
    cfg->sweep_rad = 1.5f * DEG;
    cfg->sweep_speed = 5.0f * DEG;
    cfg->sweep_accel = 1.0f;
    cfg->sweep_window_rad = 0.5f * DEG;
    cfg->joints = (uint32_t)((1ull << ARM_N_JOINTS) - 1u);
}

int arm_commission_init(arm_commission_t *c, const arm_cm_config_t *cfg, float period_s,
                        const float q0[ARM_N_JOINTS])
{
    memset(c, 0, sizeof(*c));
    c->cfg = *cfg;
    c->period_s = period_s;
    c->joint = -1;
    c->why_joint = -1;
    const float turn = cfg->sweep_speed * cfg->sweep_speed / (2.0f * cfg->sweep_accel);
    if (!(period_s > 0.0f && cfg->trip_rad > 0.0f && cfg->bound_rad > cfg->trip_rad &&
          cfg->bound_rad > cfg->sweep_rad && cfg->sweep_rad > cfg->sweep_window_rad + turn &&
          cfg->sweep_window_rad > 0.0f && cfg->pulse_max_s > 0.0f && cfg->settle_s > cfg->hold_window_s &&
          cfg->first_settle_s >= cfg->settle_s && cfg->hold_window_s > 0.0f)) {
        return -1;
    }
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        if ((cfg->joints & (1u << i)) != 0u && !(cfg->pulse_nm[i] > 0.0f && isfinite(cfg->pulse_nm[i]))) return -1;
        c->q0[i] = q0[i];
        c->j[i].q0 = q0[i];
    }
    return 0;
}

static int next_joint(const arm_commission_t *c, int after)
{
    for (int i = after + 1; i < ARM_N_JOINTS; ++i) {
        if ((c->cfg.joints & (1u << i)) != 0u) return i;
    }
    return -1;
}

static void begin_step(arm_commission_t *c, int step)
{
    c->step = step;
    c->t = 0.0f;
    c->k = 0u;
    c->began = 1; /* this period is the step's first: its clock starts at 0 next period too */
    c->hold_sum = 0.0f;
    c->hold_n = 0u;
    memset(c->fit_s, 0, sizeof(c->fit_s));
    memset(c->fit_q, 0, sizeof(c->fit_q));
}

/* The sweep's legs: q0 -> -A -> +A -> -A -> q0, each a move at the sweep's speed. */
static void begin_leg(arm_commission_t *c, int leg)
{
    static const float k_to[4] = {-1.0f, 1.0f, -1.0f, 0.0f};
    static const float k_from[4] = {0.0f, -1.0f, 1.0f, -1.0f};
    const int j = c->joint;
    float from[ARM_N_JOINTS], to[ARM_N_JOINTS];
    memcpy(from, c->q0, sizeof(from));
    memcpy(to, c->q0, sizeof(to));
    from[j] += k_from[leg] * c->cfg.sweep_rad;
    to[j] += k_to[leg] * c->cfg.sweep_rad;
    c->sweep_leg_index = leg;
    (void)arm_move_plan(&c->sweep_leg, from, to, c->cfg.sweep_speed, c->cfg.sweep_accel);
    c->t = 0.0f;
    c->began = 1;
}

/* q(t) - q_start = c0 + c1 k + c2 k^2 over the pulse's periods k; a = 2 c2 / T^2. */
static float fitted_accel(const arm_commission_t *c)
{
    const double *s = c->fit_s, *y = c->fit_q;
    /* the normal equations [s0 s1 s2; s1 s2 s3; s2 s3 s4] x = y, by Cramer's rule */
    const double a11 = s[0], a12 = s[1], a13 = s[2], a22 = s[2], a23 = s[3], a33 = s[4];
    const double det = a11 * (a22 * a33 - a23 * a23) - a12 * (a12 * a33 - a23 * a13) + a13 * (a12 * a23 - a22 * a13);
    if (!(fabs(det) > 0.0)) return 0.0f;
    const double det3 = a11 * (a22 * y[2] - y[1] * a23) - a12 * (a12 * y[2] - y[1] * a13) + y[0] * (a12 * a23 - a22 * a13);
    const double c2 = det3 / det;
    const double T = (double)c->period_s;
    return (float)(2.0 * c2 / (T * T));
}

static void hold_all(const arm_commission_t *c, arm_ctl_input_t *in)
{
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        in->q_d[i] = c->q0[i];
        in->qd_d[i] = 0.0f;
        in->qdd_d[i] = 0.0f;
    }
    in->torque_override_mask = 0u;
}

static arm_cm_status_t stop(arm_commission_t *c, arm_cm_status_t why, int joint, float value, arm_ctl_input_t *in)
{
    c->status = why;
    c->why_joint = joint;
    c->why_value = value;
    hold_all(c, in);
    return why;
}

static arm_cm_status_t settle(arm_commission_t *c, arm_ctl_input_t *in, const float tau_last[ARM_N_JOINTS])
{
    const int first = c->joint == next_joint(c, -1) && c->step == STEP_SETTLE0;
    const float length = first ? c->cfg.first_settle_s : c->cfg.settle_s;
    hold_all(c, in);
    if (c->t >= length - c->cfg.hold_window_s) {
        c->hold_sum += tau_last[c->joint];
        c->hold_n++;
    }
    if (c->t + 0.5f * c->period_s < length) return ARM_CM_RUNNING;
    const int j = c->joint;
    if (c->step == STEP_SETTLE0 || c->step == STEP_SETTLE2) { /* a pulse follows: its holding torque */
        arm_cm_pulse_t *p = &c->j[j].pulse[c->step == STEP_SETTLE0 ? 0 : 1];
        p->tau_hold = c->hold_n > 0u ? c->hold_sum / (float)c->hold_n : tau_last[j];
        p->delta = c->step == STEP_SETTLE0 ? c->cfg.pulse_nm[j] : -c->cfg.pulse_nm[j];
        c->pulse_tau = p->tau_hold + p->delta;
    }
    if (c->step == STEP_SETTLE3) {
        c->j[j].tested = 1;
        const int next = next_joint(c, j);
        if (next < 0) {
            c->joint = -1;
            c->status = ARM_CM_DONE;
            return ARM_CM_DONE;
        }
        c->joint = next;
        begin_step(c, STEP_SETTLE0);
        return ARM_CM_RUNNING;
    }
    begin_step(c, c->step + 1);
    if (c->step == STEP_SWEEP) {
        begin_leg(c, 0);
        c->j[j].sweep.speed = c->cfg.sweep_speed;
    }
    return ARM_CM_RUNNING;
}

static arm_cm_status_t pulse(arm_commission_t *c, const float q[ARM_N_JOINTS], arm_ctl_input_t *in)
{
    const int j = c->joint;
    arm_cm_pulse_t *p = &c->j[j].pulse[c->step == STEP_PULSE_POS ? 0 : 1];
    hold_all(c, in);
    if (c->k == 0u) p->q_start = q[j];
    in->q_d[j] = q[j]; /* open loop: no following error to speak of */
    in->torque_override_mask = 1u << j;
    in->tau_override[j] = c->pulse_tau;
    const double x = (double)c->k, y = (double)(q[j] - p->q_start);
    double xi = 1.0;
    for (int i = 0; i < 5; ++i) {
        c->fit_s[i] += xi;
        if (i < 3) c->fit_q[i] += y * xi;
        xi *= x;
    }
    p->samples = c->k + 1u;
    const float moved = q[j] - p->q_start;
    p->moved = moved;
    p->duration_s = c->t;
    if (fabsf(moved) < c->cfg.trip_rad && c->t < c->cfg.pulse_max_s) return ARM_CM_RUNNING;
    p->accel = fitted_accel(c);
    hold_all(c, in); /* this period already holds again */
    if (fabsf(moved) < c->cfg.trip_rad) return stop(c, ARM_CM_STUCK, j, moved, in);
    if ((moved > 0.0f) != (p->delta > 0.0f)) return stop(c, ARM_CM_REVERSED, j, moved, in);
    begin_step(c, c->step + 1);
    return ARM_CM_RUNNING;
}

static arm_cm_status_t sweep(arm_commission_t *c, const float q[ARM_N_JOINTS], const float tau_last[ARM_N_JOINTS],
                             arm_ctl_input_t *in)
{
    const int j = c->joint;
    arm_cm_sweep_t *s = &c->j[j].sweep;
    hold_all(c, in);
    arm_move_eval(&c->sweep_leg, c->t, in->q_d, in->qd_d, in->qdd_d);
    /* last period's torque went with last period's state: both the legs' middles, at full speed */
    const int cruising = in->qdd_d[j] == 0.0f && fabsf(in->qd_d[j]) > 0.0f;
    if (cruising && fabsf(q[j] - c->q0[j]) < c->cfg.sweep_window_rad) {
        if (c->sweep_leg_index == 1) {
            s->tau_up += tau_last[j];
            s->q_up += q[j];
            s->n_up++;
        } else if (c->sweep_leg_index == 2) {
            s->tau_down += tau_last[j];
            s->q_down += q[j];
            s->n_down++;
        }
    }
    if (c->t + 0.5f * c->period_s < c->sweep_leg.t_total) return ARM_CM_RUNNING;
    if (c->sweep_leg_index < 3) {
        begin_leg(c, c->sweep_leg_index + 1);
        return ARM_CM_RUNNING;
    }
    if (s->n_up > 0u) {
        s->tau_up /= (float)s->n_up;
        s->q_up /= (float)s->n_up;
    }
    if (s->n_down > 0u) {
        s->tau_down /= (float)s->n_down;
        s->q_down /= (float)s->n_down;
    }
    begin_step(c, c->step + 1);
    return ARM_CM_RUNNING;
}

arm_cm_status_t arm_commission_step(arm_commission_t *c, const float q[ARM_N_JOINTS], const float tau_last[ARM_N_JOINTS],
                                    arm_ctl_input_t *in)
{
    if (c->status != ARM_CM_RUNNING) {
        hold_all(c, in);
        return c->status;
    }
    if (c->joint < 0) {
        c->joint = next_joint(c, -1);
        begin_step(c, STEP_SETTLE0);
        if (c->joint < 0) return stop(c, ARM_CM_DONE, -1, 0.0f, in);
    }
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float away = fabsf(q[i] - c->q0[i]);
        if (away > c->j[i].excursion) c->j[i].excursion = away;
        if (!(away <= c->cfg.bound_rad)) return stop(c, ARM_CM_LEFT_BOUND, i, q[i] - c->q0[i], in);
    }
    arm_cm_status_t st;
    switch (c->step) {
    case STEP_PULSE_POS:
    case STEP_PULSE_NEG: st = pulse(c, q, in); break;
    case STEP_SWEEP: st = sweep(c, q, tau_last, in); break;
    default: st = settle(c, in, tau_last); break;
    }
    if (!c->began) {
        c->t += c->period_s;
        c->k++;
    }
    c->began = 0;
    return st;
}

const char *arm_cm_status_str(arm_cm_status_t s)
{
    switch (s) {
    case ARM_CM_RUNNING: return "running";
    case ARM_CM_DONE: return "done";
    case ARM_CM_LEFT_BOUND: return "left-bound";
    case ARM_CM_REVERSED: return "reversed";
    case ARM_CM_STUCK: return "stuck";
    }
    return "?";
}

const char *arm_cm_step_str(const arm_commission_t *c)
{
    static const char *const k_steps[STEPS] = {"settle", "pulse+", "settle", "sweep", "settle", "pulse-", "settle"};
    return c->step >= 0 && c->step < STEPS ? k_steps[c->step] : "?";
}
