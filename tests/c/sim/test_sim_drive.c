/* The emulated drive behaves like a CiA 402 drive: state machine, limit, command timeout, and its
 * power stage stops as sim_power_stage.h says (brake, quick stop ramp, fault reaction). */
#include <math.h>

#include "check.h"
#include "sim_drive.h"

#define DT 0.001

/* One period at joint velocity qd: the torque the drive applies. */
static double period(sim_drive_t *d, double qd)
{
    return sim_drive_period(d, qd, DT);
}

static sim_drive_t enabled_drive(void)
{
    sim_drive_t d;
    sim_drive_init(&d, 1, 28.0, 3);
    sim_drive_on_nmt(&d, SIM_NMT_START);
    sim_drive_on_command(&d, 0x06, 0.0);
    sim_drive_on_command(&d, 0x07, 0.0);
    sim_drive_on_command(&d, 0x0F, 0.0);
    return d;
}

static void enable_sequence_reaches_operation_enabled(void)
{
    sim_power_t s = SIM_PS_SWITCH_ON_DISABLED;
    CHECK(sim_cia402_next(s, 0x0F, 0, 0) == s); /* enable operation from disabled is not a transition */
    s = sim_cia402_next(s, 0x06, 0, 0);
    CHECK(s == SIM_PS_READY_TO_SWITCH_ON);
    s = sim_cia402_next(s, 0x07, 0x06, 0);
    CHECK(s == SIM_PS_SWITCHED_ON);
    s = sim_cia402_next(s, 0x0F, 0x07, 0);
    CHECK(s == SIM_PS_OPERATION_ENABLED);
    CHECK(((unsigned)s & 0x006Fu) == 0x0027u);
    /* CiA 402: enable operation from ready to switch on is transitions 3 and 4 */
    CHECK(sim_cia402_next(SIM_PS_READY_TO_SWITCH_ON, 0x0F, 0x06, 0) == SIM_PS_OPERATION_ENABLED);
}

static void quick_stop_ends_as_the_option_code_says(void)
{
    /* 0x605A 0: to switch on disabled at once; 1-8: quick stop active (the power stage ramps, then
     * 1-4 end in switch on disabled), left by enable operation or disable voltage and nothing else */
    CHECK(sim_cia402_next(SIM_PS_OPERATION_ENABLED, 0x02, 0x0F, 0) == SIM_PS_SWITCH_ON_DISABLED);
    CHECK(sim_cia402_next(SIM_PS_OPERATION_ENABLED, 0x02, 0x0F, 2) == SIM_PS_QUICK_STOP_ACTIVE);
    const sim_power_t q = sim_cia402_next(SIM_PS_OPERATION_ENABLED, 0x02, 0x0F, 6);
    CHECK(q == SIM_PS_QUICK_STOP_ACTIVE && ((unsigned)q & 0x006Fu) == 0x0007u);
    CHECK(sim_cia402_next(q, 0x06, 0x02, 6) == q && sim_cia402_next(q, 0x07, 0x02, 6) == q);
    CHECK(sim_cia402_next(q, 0x0F, 0x02, 6) == SIM_PS_OPERATION_ENABLED);
    CHECK(sim_cia402_next(q, 0x0F, 0x02, 2) == q); /* 1-4: it ends in switch on disabled, no way back */
    CHECK(sim_cia402_next(q, 0x00, 0x02, 6) == SIM_PS_SWITCH_ON_DISABLED);
    CHECK(sim_cia402_next(SIM_PS_SWITCHED_ON, 0x02, 0x07, 6) == SIM_PS_SWITCH_ON_DISABLED);
}

static void torque_only_in_operation_enabled_and_limited(void)
{
    sim_drive_t d;
    sim_drive_init(&d, 2, 28.0, 3);
    sim_drive_on_command(&d, 0x0F, 10.0);
    CHECK(period(&d, 0.0) == 0.0); /* NMT pre-operational: PDOs ignored */
    d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 28.000001); /* the limit, as the wire's 1 uNm rounds it */
    CHECK(period(&d, 0.0) == 28.0 && sim_drive_applied_torque(&d) == 28.0);
    sim_drive_on_command(&d, 0x0F, -28.0);
    CHECK(period(&d, 0.0) == -28.0);
    sim_drive_on_command(&d, 0x06, 5.0); /* shutdown: no brake, off at once */
    CHECK(d.power == SIM_PS_READY_TO_SWITCH_ON && period(&d, 0.0) == 0.0);
}

static void a_command_above_the_limit_faults_the_drive(void)
{
    sim_drive_t d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 100.0); /* refused, not clamped: the fault reaction, not 100 N m */
    CHECK(d.power == SIM_PS_FAULT_REACTION && period(&d, 0.0) == 0.0);
    CHECK(d.error_code == SIM_ERR_TORQUE_ABOVE_LIMIT && d.n_emcy_pending == 1u &&
          d.emcy_pending[0] == SIM_EMCY_TORQUE_LIMIT);
    for (int k = 0; k < 20; ++k) period(&d, 0.0); /* at standstill: the reaction ends, no brake to wait for */
    CHECK(d.power == SIM_PS_FAULT);
    d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, -28.01);
    CHECK(d.power == SIM_PS_FAULT_REACTION);
}

static void missing_commands_fault_the_drive_with_emcy(void)
{
    sim_drive_t d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 3.0);
    sim_drive_on_period_end(&d, 1);
    for (int i = 0; i < 2; ++i) {
        sim_drive_on_period_end(&d, 0);
        CHECK(d.power == SIM_PS_OPERATION_ENABLED);
    }
    sim_drive_on_period_end(&d, 0);
    CHECK(d.power == SIM_PS_FAULT_REACTION);
    CHECK(d.n_emcy_pending == 1u && d.emcy_pending[0] == SIM_EMCY_RPDO_TIMEOUT);
    CHECK(d.commands_missed == 3u && d.error_code == SIM_ERR_COMMAND_TIMEOUT);
    sim_drive_fault(&d, 9, 0x1234); /* already in fault: no second EMCY */
    CHECK(d.n_emcy_pending == 1u && d.error_code == SIM_ERR_COMMAND_TIMEOUT);
}

static void fault_reset_needs_a_rising_edge(void)
{
    CHECK(sim_cia402_next(SIM_PS_FAULT, 0x80, 0x80, 0) == SIM_PS_FAULT);
    CHECK(sim_cia402_next(SIM_PS_FAULT, 0x80, 0x00, 0) == SIM_PS_SWITCH_ON_DISABLED);
    CHECK(sim_cia402_next(SIM_PS_FAULT, 0x0F, 0x00, 0) == SIM_PS_FAULT);
}

/* NMT stop while enabled: the drive quick-stops (CiA 402's abort connection) from the torque it
 * applied, then, at standstill, is disabled; PDOs are ignored meanwhile. */
static void nmt_stop_quick_stops_the_drive(void)
{
    sim_drive_t d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 3.0);
    CHECK(period(&d, 0.0) == 3.0);
    CHECK(sim_drive_on_nmt(&d, SIM_NMT_STOP) == 1);
    CHECK(d.nmt_state == SIM_NMT_STATE_STOPPED && d.power == SIM_PS_QUICK_STOP_ACTIVE);
    CHECK(period(&d, 0.0) == 3.0); /* its loop takes over the torque it applied */
    CHECK(sim_drive_on_nmt(&d, SIM_NMT_STOP) == 0); /* no change, no heartbeat */
    sim_drive_on_command(&d, 0x0F, 5.0);              /* stopped: PDOs ignored */
    CHECK(period(&d, 0.0) == 3.0);
    for (int k = 0; k < 20; ++k) period(&d, 0.0);
    CHECK(d.power == SIM_PS_SWITCH_ON_DISABLED && period(&d, 0.0) == 0.0);
}

/* The brake under automatic brake control: engaged at power-on, open only after its release delay
 * in operation enabled; told to close when the drive leaves it, while the power stage holds the
 * joint for the closing delay, after which the new state is reported and the torque is gone. */
static void the_brake_opens_and_closes_with_its_delays(void)
{
    sim_drive_t d;
    sim_drive_init(&d, 1, 150.0, 3);
    const sim_brake_config_t brake = {150.0, 0.050, 0.080};
    sim_drive_set_stopping(&d, &brake, 2.0, 10.0);
    CHECK(sim_power_stage_brake_nm(&d.ps) == 150.0); /* engaged at power-on */
    sim_drive_on_nmt(&d, SIM_NMT_START);
    sim_drive_on_command(&d, 0x06, 0.0);
    sim_drive_on_command(&d, 0x07, 0.0);
    sim_drive_on_command(&d, 0x0F, 40.0);
    int k = 0;
    while (sim_power_stage_brake_nm(&d.ps) > 0.0 && k < 1000) {
        CHECK(period(&d, 0.0) == 40.0); /* the target torque flows while the brake opens */
        ++k;
    }
    CHECK(k == 80); /* its release delay */
    sim_drive_on_command(&d, 0x06, 40.0); /* shutdown */
    k = 0;
    while (d.power == SIM_PS_OPERATION_ENABLED && k < 1000) {
        CHECK(sim_power_stage_brake_nm(&d.ps) == 0.0); /* not closed yet */
        CHECK(fabs(period(&d, 0.0) - 40.0) < 1e-9);   /* holding */
        ++k;
    }
    CHECK(k == 50); /* the closing delay, powered */
    CHECK(d.power == SIM_PS_READY_TO_SWITCH_ON && sim_power_stage_brake_nm(&d.ps) == 150.0 && period(&d, 0.0) == 0.0);
}

/* An enabled drive of 150 N m with a brake (150 N m, 50 ms to close, at once to open), a 2 kg m^2
 * joint and 10 rad/s^2 of quick stop, told 20 N m. */
static sim_drive_t braked_drive(void)
{
    const sim_brake_config_t brake = {150.0, 0.050, 0.0};
    sim_drive_t d;
    sim_drive_init(&d, 1, 150.0, 3);
    sim_drive_set_stopping(&d, &brake, 2.0, 10.0);
    sim_drive_on_nmt(&d, SIM_NMT_START);
    sim_drive_on_command(&d, 0x06, 0.0);
    sim_drive_on_command(&d, 0x0F, 20.0);
    return d;
}

/* A quick stop ramps the joint's velocity to zero at the drive's deceleration, then brakes and
 * disables; a fault reaction does the same and ends in fault; a lost supply drops the torque at
 * once and the spring-applied brake closes after its delay. */
static void quick_stop_fault_reaction_and_power_loss(void)
{
    sim_drive_t d = braked_drive();
    period(&d, 0.5);
    period(&d, 0.5);
    sim_drive_on_command(&d, 0x02, 20.0); /* quick stop, moving at 0.5 rad/s */
    CHECK(d.power == SIM_PS_QUICK_STOP_ACTIVE);
    /* a joint that keeps moving at 0.5 rad/s: the loop's torque against it grows as the reference ramps down */
    const double first = period(&d, 0.5);
    CHECK(fabs(first - 20.0) <= 2.0 * 6.283185307179586 * 25.0 * 10.0 * DT + 1e-9); /* from the torque it applied */
    double v = 0.5, tau = first;
    int k = 0;
    while (d.ps.v_ref > 0.0 && k < 1000) {
        tau = period(&d, v);
        ++k;
    }
    CHECK(k >= 48 && k <= 50);              /* 0.5 rad/s at 10 rad/s^2: 50 ms */
    CHECK(tau < 20.0 - 2.0 * 2.0 * 6.2);    /* the loop (2 pi 25 Hz x 2 kg m^2) pushes against the motion */
    for (k = 0; k < 20; ++k) period(&d, 0.0); /* standstill: the brake is told to close */
    CHECK(d.power == SIM_PS_QUICK_STOP_ACTIVE && d.ps.brake_state == SIM_BRAKE_CLOSING);
    for (k = 0; k < 50; ++k) period(&d, 0.0);
    CHECK(d.power == SIM_PS_SWITCH_ON_DISABLED && sim_power_stage_brake_nm(&d.ps) == 150.0);

    d = braked_drive();
    period(&d, 0.0);
    sim_drive_fault(&d, SIM_ERR_COMMAND_TIMEOUT, SIM_EMCY_RPDO_TIMEOUT);
    CHECK(d.power == SIM_PS_FAULT_REACTION && fabs(period(&d, 0.0) - 20.0) < 1e-9);
    for (k = 0; k < 100; ++k) period(&d, 0.0);
    CHECK(d.power == SIM_PS_FAULT && sim_power_stage_brake_nm(&d.ps) == 150.0 && period(&d, 0.0) == 0.0);

    d = braked_drive();
    period(&d, 0.0);
    sim_power_stage_power_lost(&d.ps, &d.power);
    for (k = 0; k < 49; ++k) CHECK(period(&d, 0.0) == 0.0 && sim_power_stage_brake_nm(&d.ps) == 0.0);
    period(&d, 0.0);
    CHECK(sim_power_stage_brake_nm(&d.ps) == 150.0); /* spring-applied: closed on its own */
}

/* A drive's error code says why it stopped: no two reasons may share a code. */
static void every_error_code_is_its_own(void)
{
    const unsigned codes[] = {SIM_ERR_NONE, SIM_ERR_COMMAND_TIMEOUT, SIM_ERR_CONTROLLER_LOST, SIM_ERR_DIVERGED,
                              SIM_ERR_TORQUE_ABOVE_LIMIT, SIM_ERR_TWO_MASTERS, SIM_ERR_SYNC_SEQUENCE};
    const unsigned n = sizeof(codes) / sizeof(codes[0]);
    for (unsigned i = 0; i < n; ++i) {
        for (unsigned j = i + 1u; j < n; ++j) {
            CHECK(codes[i] != codes[j]);
        }
    }
}

int main(void)
{
    every_error_code_is_its_own();
    enable_sequence_reaches_operation_enabled();
    quick_stop_ends_as_the_option_code_says();
    torque_only_in_operation_enabled_and_limited();
    a_command_above_the_limit_faults_the_drive();
    missing_commands_fault_the_drive_with_emcy();
    fault_reset_needs_a_rising_edge();
    nmt_stop_quick_stops_the_drive();
    the_brake_opens_and_closes_with_its_delays();
    quick_stop_fault_reaction_and_power_loss();
    TEST_MAIN_END();
}
