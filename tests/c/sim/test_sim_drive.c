/* The emulated drive behaves like a CiA 402 drive: state machine, limit, command timeout. */
#include "check.h"
#include "sim_drive.h"

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
    /* 0x605A 0-4: to switch on disabled; 5-8: quick stop active, left by enable operation or
     * disable voltage and by nothing else */
    CHECK(sim_cia402_next(SIM_PS_OPERATION_ENABLED, 0x02, 0x0F, 2) == SIM_PS_SWITCH_ON_DISABLED);
    const sim_power_t q = sim_cia402_next(SIM_PS_OPERATION_ENABLED, 0x02, 0x0F, 6);
    CHECK(q == SIM_PS_QUICK_STOP_ACTIVE && ((unsigned)q & 0x006Fu) == 0x0007u);
    CHECK(sim_cia402_next(q, 0x06, 0x02, 6) == q && sim_cia402_next(q, 0x07, 0x02, 6) == q);
    CHECK(sim_cia402_next(q, 0x0F, 0x02, 6) == SIM_PS_OPERATION_ENABLED);
    CHECK(sim_cia402_next(q, 0x00, 0x02, 6) == SIM_PS_SWITCH_ON_DISABLED);
    CHECK(sim_cia402_next(SIM_PS_SWITCHED_ON, 0x02, 0x07, 6) == SIM_PS_SWITCH_ON_DISABLED);
}

static void torque_only_in_operation_enabled_and_limited(void)
{
    sim_drive_t d;
    sim_drive_init(&d, 2, 28.0, 3);
    sim_drive_on_command(&d, 0x0F, 10.0);
    CHECK(sim_drive_applied_torque(&d) == 0.0); /* NMT pre-operational: PDOs ignored */
    d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 28.000001); /* the limit, as the wire's 1 uNm rounds it */
    CHECK(sim_drive_applied_torque(&d) == 28.0);
    sim_drive_on_command(&d, 0x0F, -28.0);
    CHECK(sim_drive_applied_torque(&d) == -28.0);
    sim_drive_on_command(&d, 0x06, 5.0); /* shutdown */
    CHECK(d.power == SIM_PS_READY_TO_SWITCH_ON && sim_drive_applied_torque(&d) == 0.0);
}

static void a_command_above_the_limit_faults_the_drive(void)
{
    sim_drive_t d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 100.0); /* refused, not clamped */
    CHECK(d.power == SIM_PS_FAULT && sim_drive_applied_torque(&d) == 0.0);
    CHECK(d.error_code == SIM_ERR_TORQUE_ABOVE_LIMIT && d.n_emcy_pending == 1u &&
          d.emcy_pending[0] == SIM_EMCY_TORQUE_LIMIT);
    d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, -28.01);
    CHECK(d.power == SIM_PS_FAULT);
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
    CHECK(d.power == SIM_PS_FAULT && sim_drive_applied_torque(&d) == 0.0);
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

static void nmt_stop_removes_torque(void)
{
    sim_drive_t d = enabled_drive();
    sim_drive_on_command(&d, 0x0F, 3.0);
    CHECK(sim_drive_applied_torque(&d) == 3.0);
    CHECK(sim_drive_on_nmt(&d, SIM_NMT_STOP) == 1);
    CHECK(d.nmt_state == SIM_NMT_STATE_STOPPED && sim_drive_applied_torque(&d) == 0.0);
    CHECK(sim_drive_on_nmt(&d, SIM_NMT_STOP) == 0); /* no change, no heartbeat */
    sim_drive_on_command(&d, 0x0F, 3.0);              /* stopped: PDOs ignored */
    CHECK(sim_drive_applied_torque(&d) == 0.0);
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
    nmt_stop_removes_torque();
    TEST_MAIN_END();
}
