/* Behaviour of the safety layer after the method: each rule as a scenario. */
#include <math.h>
#include <string.h>

#include "arm/controller.h"
#include "arm_robot_model_data.h"
#include "check.h"

#define ALL ((uint32_t)((1u << ARM_N_JOINTS) - 1u))

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
static void step(arm_ctl_t *ctl, arm_ctl_input_t *in, arm_ctl_output_t *out)
{
    arm_ctl_step(ctl, in, out);
    memcpy(in->tau_measured, out->tau, sizeof(in->tau_measured));
}

static void start(arm_ctl_t *ctl, arm_ctl_config_t *cfg)
{
    arm_ctl_default_config(&ARM_ROBOT_MODEL, cfg);
    CHECK(arm_ctl_init(ctl, &ARM_ROBOT_MODEL, cfg) == ARM_CTL_OK);
}

static void test_starts_in_init_with_zero_torque(void)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    start(&ctl, &cfg);
    home_input(&in);
    in.fresh_mask = 0u;
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_INIT);
    for (int j = 0; j < ARM_N_JOINTS; ++j) CHECK(out.tau[j] == 0.0f);
    in.fresh_mask = ALL;
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_RUNNING);
}

static void test_nan_input_gives_safe_stop_and_zero_torque(void)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    start(&ctl, &cfg);
    home_input(&in);
    for (int k = 0; k < 50; ++k) step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_RUNNING);
    CHECK(fabsf(out.tau[1]) > 1.0f); /* holding the shoulder against gravity */
    in.qd[2] = NAN;
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_FAULT);
    CHECK(out.fault == ARM_FAULT_NONFINITE_INPUT);
    for (int j = 0; j < ARM_N_JOINTS; ++j) CHECK(out.tau[j] == 0.0f);
    /* Latched: good input afterwards does not restart the arm. */
    in.qd[2] = 0.0f;
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_SAFE_STOP);
    CHECK(out.fault == ARM_FAULT_NONFINITE_INPUT);
    for (int j = 0; j < ARM_N_JOINTS; ++j) CHECK(out.tau[j] == 0.0f);
}

static void test_torque_and_rate_limits(void)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.checks &= ~ARM_CHECK_FOLLOWING_ERROR; /* the huge error below is the point here */
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_OK);
    home_input(&in);
    in.q_d[3] += 10.0f; /* a huge error demands far more than the wrist's 28 Nm */
    float prev[ARM_N_JOINTS] = {0};
    for (int k = 0; k < 100; ++k) {
        step(&ctl, &in, &out);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            CHECK(fabsf(out.tau[j]) <= cfg.torque_limit[j]);
            CHECK(fabsf(out.tau[j] - prev[j]) <= cfg.torque_rate_limit[j] * (1.0f + 1e-6f));
            prev[j] = out.tau[j];
        }
    }
    CHECK(fabsf(out.tau[3]) == cfg.torque_limit[3]);
    CHECK((out.saturated_mask & (1u << 3)) != 0u);
    CHECK(out.state == ARM_STATE_RUNNING);
}

static void test_watchdog_trips_after_configured_stale_periods(void)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.watchdog_periods = 4u;
    cfg.safe_stop_mode = ARM_SAFE_STOP_DAMPING;
    cfg.safe_stop_damping = 2.0f;
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_OK);
    home_input(&in);
    in.qd[0] = 0.5f;
    step(&ctl, &in, &out);
    in.fresh_mask = ALL & ~(1u << 4); /* drive 5 goes quiet */
    for (uint32_t k = 0; k < cfg.watchdog_periods; ++k) {
        step(&ctl, &in, &out);
        CHECK(out.state == ARM_STATE_RUNNING); /* within the watchdog: last state is held */
    }
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_FAULT);
    CHECK(out.fault == ARM_FAULT_STALE_INPUT);
    CHECK(fabsf(out.tau[0] - (-2.0f * 0.5f)) < 1e-6f); /* damping safe stop uses the last qd */
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
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    start(&ctl, &cfg);
    home_input(&in);
    step(&ctl, &in, &out);
    arm_ctl_external_fault(&ctl);
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_FAULT && out.fault == ARM_FAULT_EXTERNAL);
    for (int j = 0; j < ARM_N_JOINTS; ++j) CHECK(out.tau[j] == 0.0f);
}

/* Runs the arm at its home pose for a while, then applies `spoil` to one period's input: the
 * next output must be that fault, on that joint, with zero torque. */
static void expect_fault(void (*spoil)(arm_ctl_input_t *), arm_fault_t fault, int joint, uint32_t periods)
{
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    start(&ctl, &cfg);
    home_input(&in);
    for (int k = 0; k < 20; ++k) step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_RUNNING);
    for (uint32_t k = 0; k < periods; ++k) {
        spoil(&in);
        step(&ctl, &in, &out);
        if (k + 1u < periods) CHECK(out.state == ARM_STATE_RUNNING); /* tolerated so far */
    }
    CHECK_MSG(out.state == ARM_STATE_FAULT && out.fault == fault && out.fault_joint == joint,
              "state %d fault %s joint %d", (int)out.state, arm_fault_str(out.fault), out.fault_joint);
    for (int j = 0; j < ARM_N_JOINTS; ++j) CHECK(out.tau[j] == 0.0f);
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
    arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    start(&ctl, &cfg);
    home_input(&in);
    for (int k = 0; k < 1000; ++k) { /* 1 rad/s on every joint for 1 s, consistent steps, inside the ranges */
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            in.qd[j] = 1.0f;
            in.q[j] += 0.001f;
            in.q_d[j] = in.q[j] + 0.01f;
        }
        step(&ctl, &in, &out);
    }
    CHECK(out.state == ARM_STATE_RUNNING);
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.checks = 0u;
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_OK);
    home_input(&in);
    step(&ctl, &in, &out);
    spoof_velocity(&in);
    step(&ctl, &in, &out);
    CHECK(out.state == ARM_STATE_RUNNING); /* off is off */
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.following_error_limit[0] = 0.0f;
    CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_BAD_FOLLOWING_LIMIT);
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
    test_nan_input_gives_safe_stop_and_zero_torque();
    test_torque_and_rate_limits();
    test_watchdog_trips_after_configured_stale_periods();
    test_bad_config_refused();
    test_each_bad_limit_is_named();
    test_external_fault_latches();
    test_plausibility_faults_name_the_joint();
    test_plausible_motion_and_disabled_checks_pass();
    TEST_MAIN_END();
}
