/* Commissioning's sequence (arm/commission.h) against joints simulated here: each an inertia with a
 * constant gravity torque, viscous damping and Coulomb friction that sticks, held by a PD with the
 * gravity known (the controller's hold), or driven open loop by the sequence's pulses. What it
 * measures is what the joints are; a reversed joint, a stuck one and one that runs away end it,
 * naming the joint. */
#include <math.h>
#include <string.h>

#include "arm/commission.h"
#include "check.h"

#define N ARM_N_JOINTS
#define DT 0.001f

typedef struct {
    float inertia[N], gravity[N], damping[N], friction[N];
    float sign[N];       /* -1: the motor turns the other way */
    float model_g[N];    /* the gravity the hold compensates (the model's) */
    float q[N], qd[N];
} joints_t;

static void joints_default(joints_t *s)
{
    memset(s, 0, sizeof(*s));
    for (int j = 0; j < N; ++j) {
        s->inertia[j] = 0.5f + 0.5f * (float)j;
        s->gravity[j] = j == 1 ? -30.0f : (j == 2 ? -12.0f : 0.0f);
        s->model_g[j] = s->gravity[j];
        s->damping[j] = 1.0f;
        s->friction[j] = 2.0f;
        s->sign[j] = 1.0f;
        s->q[j] = 0.1f * (float)j;
    }
}

/* One period of each joint under torque tau (semi-implicit Euler; friction sticks while it can). */
static void advance(joints_t *s, const float tau[N])
{
    for (int j = 0; j < N; ++j) {
        const float drive = s->sign[j] * tau[j] - s->gravity[j] - s->damping[j] * s->qd[j];
        float acc;
        if (fabsf(s->qd[j]) < 1e-6f && fabsf(drive) <= s->friction[j]) {
            acc = 0.0f;
            s->qd[j] = 0.0f;
        } else {
            const float dir = fabsf(s->qd[j]) >= 1e-6f ? (s->qd[j] > 0.0f ? 1.0f : -1.0f) : (drive > 0.0f ? 1.0f : -1.0f);
            acc = (drive - dir * s->friction[j]) / s->inertia[j];
            const float v = s->qd[j] + acc * DT;
            if (fabsf(s->qd[j]) >= 1e-6f && (v > 0.0f) != (s->qd[j] > 0.0f)) {
                s->qd[j] = 0.0f; /* friction stops it, it does not reverse it */
            } else {
                s->qd[j] = v;
            }
        }
        s->q[j] += s->qd[j] * DT;
    }
}

typedef struct {
    arm_cm_status_t status;
    uint32_t periods;
} outcome_t;

static outcome_t run(arm_commission_t *c, joints_t *s, uint32_t max_periods)
{
    arm_cm_config_t cfg;
    arm_commission_default_config(&cfg);
    for (int j = 0; j < N; ++j) cfg.pulse_nm[j] = 4.0f * s->friction[j] + 1.0f;
    CHECK(arm_commission_init(c, &cfg, DT, s->q) == 0);
    float tau[N] = {0};
    arm_ctl_input_t in;
    outcome_t o = {ARM_CM_RUNNING, 0u};
    for (uint32_t k = 0; k < max_periods; ++k) {
        memset(&in, 0, sizeof(in));
        o.status = arm_commission_step(c, s->q, tau, &in);
        o.periods = k;
        if (o.status != ARM_CM_RUNNING) break;
        for (int j = 0; j < N; ++j) { /* the hold: model gravity, inertia x (qdd_d + PD at 40 rad/s) */
            const float u = 1600.0f * (in.q_d[j] - s->q[j]) + 80.0f * (in.qd_d[j] - s->qd[j]) + in.qdd_d[j];
            tau[j] = ((in.torque_override_mask >> j) & 1u) ? in.tau_override[j] : s->model_g[j] + s->inertia[j] * u;
        }
        advance(s, tau);
    }
    return o;
}

static void measures_what_the_joints_are(void)
{
    static arm_commission_t c;
    joints_t s;
    joints_default(&s);
    const outcome_t o = run(&c, &s, 200000u);
    CHECK_MSG(o.status == ARM_CM_DONE, "status %s after %u periods", arm_cm_status_str(o.status), o.periods);
    for (int j = 0; j < N; ++j) {
        const arm_cm_joint_t *x = &c.j[j];
        CHECK(x->tested && x->excursion < c.cfg.bound_rad);
        CHECK(x->pulse[0].moved >= c.cfg.trip_rad && x->pulse[1].moved <= -c.cfg.trip_rad);
        const arm_cm_sweep_t *w = &x->sweep;
        CHECK(w->n_up > 50u && w->n_down > 50u);
        /* gravity: the mean of the torques across the pose; friction and damping: half their difference */
        const float g = 0.5f * (w->tau_up + w->tau_down), f = 0.5f * (w->tau_up - w->tau_down);
        CHECK_MSG(fabsf(g - s.gravity[j]) < 0.05f * s.friction[j] + 0.05f, "joint %d gravity %g, true %g", j, (double)g,
                  (double)s.gravity[j]);
        CHECK_MSG(fabsf(f - (s.friction[j] + s.damping[j] * w->speed)) < 0.1f, "joint %d friction %g", j, (double)f);
        /* scale: the fitted acceleration under a known net torque gives the inertia */
        for (int p = 0; p < 2; ++p) {
            const arm_cm_pulse_t *pu = &x->pulse[p];
            const float sign = p == 0 ? 1.0f : -1.0f;
            const float net = pu->tau_hold + pu->delta - s.gravity[j] - sign * s.friction[j];
            CHECK_MSG(fabsf(net / pu->accel / s.inertia[j] - 1.0f) < 0.15f, "joint %d pulse %d inertia %g, true %g", j, p,
                      (double)(net / pu->accel), (double)s.inertia[j]);
        }
    }
}

static void a_reversed_joint_ends_it_before_the_loop_closes(void)
{
    static arm_commission_t c;
    joints_t s;
    joints_default(&s);
    s.sign[0] = -1.0f; /* joint 0: no gravity, so the hold does not run away before its pulse */
    const outcome_t o = run(&c, &s, 200000u);
    CHECK_MSG(o.status == ARM_CM_REVERSED && c.why_joint == 0 && c.why_value < 0.0f, "%s joint %d",
              arm_cm_status_str(o.status), c.why_joint);
    /* a reversed joint under gravity runs away from the hold itself: the bound names it */
    joints_default(&s);
    s.sign[1] = -1.0f;
    const outcome_t o2 = run(&c, &s, 200000u);
    CHECK_MSG(o2.status == ARM_CM_LEFT_BOUND && c.why_joint == 1 && fabsf(c.why_value) > c.cfg.bound_rad, "%s joint %d",
              arm_cm_status_str(o2.status), c.why_joint);
}

static void a_stuck_joint_and_a_drifting_one_are_named(void)
{
    static arm_commission_t c;
    joints_t s;
    joints_default(&s);
    arm_cm_config_t cfg;
    arm_commission_default_config(&cfg);
    for (int j = 0; j < N; ++j) cfg.pulse_nm[j] = 4.0f * s.friction[j] + 1.0f;
    s.friction[3] = 100.0f; /* far above its pulse */
    CHECK(arm_commission_init(&c, &cfg, DT, s.q) == 0);
    float tau[N] = {0};
    arm_ctl_input_t in;
    arm_cm_status_t st = ARM_CM_RUNNING;
    for (uint32_t k = 0; k < 200000u && st == ARM_CM_RUNNING; ++k) {
        memset(&in, 0, sizeof(in));
        st = arm_commission_step(&c, s.q, tau, &in);
        for (int j = 0; j < N; ++j) {
            const float u = 1600.0f * (in.q_d[j] - s.q[j]) + 80.0f * (in.qd_d[j] - s.qd[j]) + in.qdd_d[j];
            tau[j] = ((in.torque_override_mask >> j) & 1u) ? in.tau_override[j] : s.model_g[j] + s.inertia[j] * u;
        }
        advance(&s, tau);
    }
    CHECK_MSG(st == ARM_CM_STUCK && c.why_joint == 3, "%s joint %d", arm_cm_status_str(st), c.why_joint);
    CHECK(c.j[0].tested && c.j[2].tested && !c.j[3].tested);
    /* a hold that cannot keep a joint (gravity far from the model's, a weak PD): the bound */
    joints_default(&s);
    s.gravity[2] = -400.0f;
    const outcome_t o = run(&c, &s, 200000u);
    CHECK_MSG(o.status == ARM_CM_LEFT_BOUND && c.why_joint == 2, "%s joint %d", arm_cm_status_str(o.status), c.why_joint);
}

static void a_configuration_that_cannot_run_is_refused(void)
{
    static arm_commission_t c;
    arm_cm_config_t cfg;
    float q[N] = {0};
    arm_commission_default_config(&cfg);
    CHECK(arm_commission_init(&c, &cfg, DT, q) == -1); /* no pulses */
    for (int j = 0; j < N; ++j) cfg.pulse_nm[j] = 1.0f;
    CHECK(arm_commission_init(&c, &cfg, DT, q) == 0);
    cfg.sweep_rad = cfg.bound_rad; /* the sweep would reach the bound */
    CHECK(arm_commission_init(&c, &cfg, DT, q) == -1);
    arm_commission_default_config(&cfg);
    for (int j = 0; j < N; ++j) cfg.pulse_nm[j] = 1.0f;
    cfg.joints = 0u; /* nothing to test: done at once, the arm held */
    CHECK(arm_commission_init(&c, &cfg, DT, q) == 0);
    arm_ctl_input_t in;
    memset(&in, 0, sizeof(in));
    CHECK(arm_commission_step(&c, q, q, &in) == ARM_CM_DONE && in.torque_override_mask == 0u);
}

int main(void)
{
    measures_what_the_joints_are();
    a_reversed_joint_ends_it_before_the_loop_closes();
    a_stuck_joint_and_a_drifting_one_are_named();
    a_configuration_that_cannot_run_is_refused();
    TEST_MAIN_END();
}
