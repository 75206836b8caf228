/* Behaviour of the safety layer after the method: each rule as a scenario. */
#include <math.h>
#include <string.h>

#include "arm/controller.h"
#include "arm/rnea.h"
#include "arm_robot_model_data.h"
#include "check.h"

#define ALL ((uint32_t)((1u << ARM_N_JOINTS) - 1u))

/* A controller under test, the input it is fed and its last output. */
typedef struct {
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
} rig_t;

static void home_input(arm_ctl_input_t *in)
{
    memset(in, 0, sizeof(*in));
    for (int j = 0; j < ARM_N_JOINTS; ++j) { /* the arm's own home (its model's keyframe) */
        in->q[j] = ARM_HOME_Q[j];
        in->q_d[j] = in->q[j];
    }
    in->fresh_mask = ALL;
}

/* One period with drives that do as told: they report the torque commanded last period. */
static void step(rig_t *r)
{
    arm_ctl_step(&r->ctl, &r->in, &r->out);
    memcpy(r->in.tau_measured, r->out.tau, sizeof(r->in.tau_measured));
}

/* The controller on r->cfg (as the test set it), the arm at home, then `periods` periods. */
static void run_from_home(rig_t *r, int periods)
{
    CHECK(arm_ctl_init(&r->ctl, &ARM_ROBOT_MODEL, &r->cfg) == ARM_CTL_OK);
    home_input(&r->in);
    for (int k = 0; k < periods; ++k) step(r);
}

/* The same on the default configuration. */
static void run_default_from_home(rig_t *r, int periods)
{
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &r->cfg);
    run_from_home(r, periods);
}

static void check_zero_torque(const rig_t *r)
{
    for (int j = 0; j < ARM_N_JOINTS; ++j) CHECK(r->out.tau[j] == 0.0f);
}

/* The safe stop's hold at pose q: the model's torque for the deceleration -rate * qd (qd NULL: at
 * rest, gravity alone). Never zero torque alone: the shoulder's share of it is the arm's weight. */
static void check_hold(const rig_t *r, const float *q, const float *qd)
{
    float rest[ARM_N_JOINTS] = {0}, acc[ARM_N_JOINTS] = {0}, want[ARM_N_JOINTS];
    for (int j = 0; j < ARM_N_JOINTS && qd != NULL; ++j) acc[j] = -r->cfg.safe_stop_rate * qd[j];
    arm_rnea(&ARM_ROBOT_MODEL, q, rest, acc, want);
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        CHECK_MSG(fabsf(r->out.tau[j] - want[j]) <= 1e-3f + 1e-5f * fabsf(want[j]), "joint %d: %g, the hold is %g", j,
                  (double)r->out.tau[j], (double)want[j]);
    }
    CHECK(fabsf(r->out.tau[1]) > 1.0f);
}

static void check_gravity_hold_at_home(const rig_t *r)
{
    float home[ARM_N_JOINTS];
    for (int j = 0; j < ARM_N_JOINTS; ++j) home[j] = ARM_HOME_Q[j];
    check_hold(r, home, NULL);
}

static void test_starts_in_init_with_zero_torque(void)
{
    rig_t r;
    run_default_from_home(&r, 0);
    r.in.fresh_mask = 0u;
    step(&r);
    CHECK(r.out.state == ARM_STATE_INIT);
    check_zero_torque(&r);
    r.in.fresh_mask = ALL;
    step(&r);
    CHECK(r.out.state == ARM_STATE_RUNNING);
}

static void test_nan_input_gives_safe_stop_and_the_hold(void)
{
    rig_t r;
    run_default_from_home(&r, 50);
    CHECK(r.out.state == ARM_STATE_RUNNING);
    CHECK(fabsf(r.out.tau[1]) > 1.0f); /* holding the shoulder against gravity */
    r.in.qd[2] = NAN;
    step(&r);
    CHECK(r.out.state == ARM_STATE_FAULT);
    CHECK(r.out.fault == ARM_FAULT_NONFINITE_INPUT);
    check_gravity_hold_at_home(&r); /* the NaN state is not used: gravity at the last good pose */
    /* Latched: good input afterwards does not restart the arm; it holds it. */
    r.in.qd[2] = 0.0f;
    step(&r);
    CHECK(r.out.state == ARM_STATE_SAFE_STOP);
    CHECK(r.out.fault == ARM_FAULT_NONFINITE_INPUT);
    check_gravity_hold_at_home(&r);
}

/* A stop without a fault holds the arm as a fault does; the hold damps a moving joint through the
 * model (the deceleration -rate * qd), and a state that fails the plausibility checks is not used. */
static void test_stop_holds_and_damps_and_ignores_implausible_states(void)
{
    rig_t r;
    run_default_from_home(&r, 20);
    arm_ctl_stop(&r.ctl);
    float q[ARM_N_JOINTS], qd[ARM_N_JOINTS] = {0};
    for (int j = 0; j < ARM_N_JOINTS; ++j) q[j] = r.in.q[j];
    qd[1] = 0.2f;
    qd[3] = -0.3f;
    for (int k = 0; k < 30; ++k) { /* constant velocities, their steps consistent; the rate limit lets it settle */
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            r.in.qd[j] = qd[j];
            q[j] += qd[j] * r.cfg.period_s;
            r.in.q[j] = q[j];
        }
        step(&r);
        CHECK(r.out.state == ARM_STATE_SAFE_STOP && r.out.fault == ARM_FAULT_NONE);
    }
    check_hold(&r, q, qd);
    r.in.q[2] = 2147.0f; /* a spoofed position: the hold stays at the last good pose, at rest */
    for (int k = 0; k < 30; ++k) step(&r);
    check_hold(&r, q, NULL);
}

static void test_torque_and_rate_limits(void)
{
    rig_t r;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &r.cfg);
    r.cfg.checks &= ~ARM_CHECK_FOLLOWING_ERROR; /* the huge error below is the point here */
    run_from_home(&r, 0);
    r.in.q_d[3] += 10.0f; /* a huge error demands far more than the wrist's 28 Nm */
    float prev[ARM_N_JOINTS] = {0};
    for (int k = 0; k < 100; ++k) {
        step(&r);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            CHECK(fabsf(r.out.tau[j]) <= r.cfg.torque_limit[j]);
            CHECK(fabsf(r.out.tau[j] - prev[j]) <= r.cfg.torque_rate_limit[j] * (1.0f + 1e-6f));
            prev[j] = r.out.tau[j];
        }
    }
    CHECK(fabsf(r.out.tau[3]) == r.cfg.torque_limit[3]);
    CHECK((r.out.saturated_mask & (1u << 3)) != 0u);
    CHECK(r.out.state == ARM_STATE_RUNNING);
}

static void test_watchdog_trips_after_configured_stale_periods(void)
{
    rig_t r;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &r.cfg);
    r.cfg.watchdog_periods = 4u;
    run_from_home(&r, 0);
    r.in.qd[0] = 0.5f;
    step(&r);
    r.in.fresh_mask = ALL & ~(1u << 4); /* drive 5 goes quiet */
    for (uint32_t k = 0; k < r.cfg.watchdog_periods; ++k) {
        step(&r);
        CHECK(r.out.state == ARM_STATE_RUNNING); /* within the watchdog: last state is held */
    }
    step(&r);
    CHECK(r.out.state == ARM_STATE_FAULT);
    CHECK(r.out.fault == ARM_FAULT_STALE_INPUT);
    for (int k = 0; k < 20; ++k) step(&r); /* within the rate limit, to the hold */
    check_gravity_hold_at_home(&r); /* stale: gravity at the last pose, no damping on an old velocity */
}

static void test_bad_config_refused(void)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.torque_limit[2] = -1.0f;
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_BAD_LIMIT);
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.kp = NAN;
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_BAD_GAIN);
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.method = ARM_METHOD_COUNT;
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_BAD_METHOD);
    CHECK(arm_method_from_str("pd") == ARM_METHOD_PD);
    CHECK(arm_method_from_str("nope") == ARM_METHOD_COUNT);
}

static void test_external_fault_latches(void)
{
    rig_t r;
    run_default_from_home(&r, 20); /* the torque has risen to the arm's weight (its rate limit) */
    arm_ctl_external_fault(&r.ctl);
    step(&r);
    CHECK(r.out.state == ARM_STATE_FAULT && r.out.fault == ARM_FAULT_EXTERNAL);
    check_gravity_hold_at_home(&r);
}

/* Runs the arm at its home pose for a while, then applies `spoil` to one period's input: the
 * next output must be that fault, on that joint, with the hold at the last good pose. */
static void expect_fault(void (*spoil)(arm_ctl_input_t *), arm_fault_t fault, int joint, uint32_t periods)
{
    rig_t r;
    run_default_from_home(&r, 20);
    CHECK(r.out.state == ARM_STATE_RUNNING);
    for (uint32_t k = 0; k < periods; ++k) {
        spoil(&r.in);
        step(&r);
        if (k + 1u < periods) CHECK(r.out.state == ARM_STATE_RUNNING); /* tolerated so far */
    }
    CHECK_MSG(r.out.state == ARM_STATE_FAULT && r.out.fault == fault && r.out.fault_joint == joint,
              "state %d fault %s joint %d", (int)r.out.state, arm_fault_str(r.out.fault), r.out.fault_joint);
    check_gravity_hold_at_home(&r);
}

static void spoof_position(arm_ctl_input_t *in) { in->q[2] = 2147.0f; }               /* INT32_MAX urad */
static void spoof_velocity(arm_ctl_input_t *in) { in->qd[4] = 2147.0f; }
static void jump_position(arm_ctl_input_t *in) { in->q[1] += 0.05f; }                 /* 50 mrad in 1 ms, qd 0 */
static void run_away(arm_ctl_input_t *in) { in->q_d[5] = in->q[5] + 0.6f; }           /* 0.6 rad behind */
static void drive_ignores(arm_ctl_input_t *in) { in->tau_measured[1] += 30.0f; }       /* not the commanded torque */

static void test_plausibility_faults_name_the_joint(void)
{
    expect_fault(spoof_position, ARM_FAULT_POSITION_RANGE, 2, 1u);
    expect_fault(spoof_velocity, ARM_FAULT_VELOCITY_LIMIT, 4, 1u);
    expect_fault(jump_position, ARM_FAULT_POSITION_STEP, 1, 1u);
    expect_fault(run_away, ARM_FAULT_FOLLOWING_ERROR, 5, 1u);
    expect_fault(drive_ignores, ARM_FAULT_TORQUE_MISMATCH, 1, 3u); /* three periods in a row */
}

static void test_plausible_motion_and_disabled_checks_pass(void)
{
    rig_t r;
    run_default_from_home(&r, 0);
    for (int k = 0; k < 1000; ++k) { /* 1 rad/s on every joint for 1 s, consistent steps, inside the ranges */
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            r.in.qd[j] = 1.0f;
            r.in.q[j] += 0.001f;
            r.in.q_d[j] = r.in.q[j] + 0.01f;
        }
        step(&r);
    }
    CHECK(r.out.state == ARM_STATE_RUNNING);
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &r.cfg);
    r.cfg.checks = 0u;
    run_from_home(&r, 1);
    spoof_velocity(&r.in);
    step(&r);
    CHECK(r.out.state == ARM_STATE_RUNNING); /* off is off */
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &r.cfg);
    r.cfg.following_error_limit[0] = 0.0f;
    CHECK(arm_ctl_init(&r.ctl, &ARM_ROBOT_MODEL, &r.cfg) == ARM_CTL_BAD_FOLLOWING_LIMIT);
}

/* Each refused limit has its own result, and its text names the setting that is wrong. */
static void test_each_bad_limit_is_named(void)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    const struct {
        arm_ctl_init_result_t want;
        const char *named;
    } cases[] = {
        {ARM_CTL_BAD_LIMIT, "torque"},           {ARM_CTL_BAD_LIMIT, "torque-rate"},
        {ARM_CTL_BAD_RANGE, "q_min < q_max"},    {ARM_CTL_BAD_VELOCITY_LIMIT, "velocity"},
        {ARM_CTL_BAD_FOLLOWING_LIMIT, "following-error"}, {ARM_CTL_BAD_MISMATCH_LIMIT, "mismatch"},
        {ARM_CTL_BAD_MISMATCH_LIMIT, "periods"}, {ARM_CTL_BAD_STEP_TOLERANCE, "step tolerance"},
    };
    for (unsigned k = 0; k < sizeof(cases) / sizeof(cases[0]); ++k) {
        arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
        const int j = ARM_N_JOINTS - 1;
        switch (k) {
        case 0: cfg.torque_limit[j] = 0.0f; break;
        case 1: cfg.torque_rate_limit[j] = INFINITY; break;
        case 2: cfg.q_min[j] = cfg.q_max[j]; break;
        case 3: cfg.velocity_limit[j] = 0.0f; break;
        case 4: cfg.following_error_limit[j] = -1.0f; break;
        case 5: cfg.torque_mismatch_limit[j] = 0.0f; break;
        case 6: cfg.torque_mismatch_periods = 0u; break;
        default: cfg.step_tolerance = 0.0f; break;
        }
        const arm_ctl_init_result_t r = arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg);
        CHECK(r == cases[k].want);
        CHECK(strstr(arm_ctl_init_result_str(r), cases[k].named) != NULL);
        /* no two settings share a text that names only one of them */
        for (unsigned m = 0; m < sizeof(cases) / sizeof(cases[0]); ++m) {
            if (cases[m].want != r) CHECK(strstr(arm_ctl_init_result_str(r), cases[m].named) == NULL ||
                                          strcmp(cases[m].named, "torque") == 0);
        }
    }
}

int main(void)
{
    test_starts_in_init_with_zero_torque();
    test_nan_input_gives_safe_stop_and_the_hold();
    test_stop_holds_and_damps_and_ignores_implausible_states();
    test_torque_and_rate_limits();
    test_watchdog_trips_after_configured_stale_periods();
    test_bad_config_refused();
    test_each_bad_limit_is_named();
    test_external_fault_latches();
    test_plausibility_faults_name_the_joint();
    test_plausible_motion_and_disabled_checks_pass();
    TEST_MAIN_END();
}
