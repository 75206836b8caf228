#include "sim_drive.h"

#define CW_FAULT_RESET 0x0080u

void sim_drive_init(sim_drive_t *d, uint8_t node_id, double torque_limit, uint32_t command_timeout_periods)
{
    *d = (sim_drive_t){0};
    d->node_id = node_id;
    d->torque_limit = torque_limit;
    d->command_timeout_periods = command_timeout_periods;
    d->nmt_state = SIM_NMT_STATE_PRE_OPERATIONAL;
    d->power = SIM_PS_SWITCH_ON_DISABLED;
    const sim_brake_config_t none = {0.0, 0.0, 0.0};
    sim_power_stage_init(&d->ps, &none, torque_limit, 0.0);
}

void sim_drive_set_stopping(sim_drive_t *d, const sim_brake_config_t *brake, double joint_inertia,
                            double quick_stop_decel)
{
    sim_power_stage_init(&d->ps, brake, d->torque_limit, joint_inertia);
    d->quick_stop_decel = quick_stop_decel;
}

/* The state machine's next state, through the power stage (quick stop option 2). */
static void move_to(sim_drive_t *d, sim_power_t next)
{
    sim_power_stage_transition(&d->ps, &d->power, next, SIM_QS_QUICK, d->quick_stop_decel, d->quick_stop_decel);
}

sim_power_t sim_cia402_next(sim_power_t state, uint16_t cw, uint16_t prev_cw, int32_t quick_stop_option)
{
    if (state == SIM_PS_FAULT_REACTION) {
        return state; /* the drive finishes its reaction first */
    }
    if (state == SIM_PS_FAULT) {
        const int rising_reset = (cw & CW_FAULT_RESET) != 0u && (prev_cw & CW_FAULT_RESET) == 0u;
        return rising_reset ? SIM_PS_SWITCH_ON_DISABLED : state;
    }
    if ((cw & 0x0082u) == 0x0000u) { /* disable voltage (transitions 7, 9, 10, 12) */
        return SIM_PS_SWITCH_ON_DISABLED;
    }
    if (state == SIM_PS_QUICK_STOP_ACTIVE) { /* left by disable voltage, above, or, with 0x605A 5-8, enable operation (16) */
        const int back = (cw & 0x008Fu) == 0x000Fu && quick_stop_option >= 5 && quick_stop_option <= 8;
        return back ? SIM_PS_OPERATION_ENABLED : state;
    }
    if ((cw & 0x0086u) == 0x0002u) { /* quick stop (7, 10, 11): from operation enabled a ramp, unless option 0 */
        const int ramps = state == SIM_PS_OPERATION_ENABLED && quick_stop_option >= 1 && quick_stop_option <= 8;
        return ramps ? SIM_PS_QUICK_STOP_ACTIVE : SIM_PS_SWITCH_ON_DISABLED;
    }
    if ((cw & 0x0087u) == 0x0006u) { /* shutdown */
        return SIM_PS_READY_TO_SWITCH_ON;
    }
    if ((cw & 0x008Fu) == 0x0007u) { /* switch on / disable operation */
        if (state == SIM_PS_READY_TO_SWITCH_ON || state == SIM_PS_SWITCHED_ON ||
            state == SIM_PS_OPERATION_ENABLED) {
            return SIM_PS_SWITCHED_ON;
        }
        return state;
    }
    if ((cw & 0x008Fu) == 0x000Fu) { /* enable operation (4); from ready to switch on, 3 then 4 */
        if (state == SIM_PS_READY_TO_SWITCH_ON || state == SIM_PS_SWITCHED_ON || state == SIM_PS_OPERATION_ENABLED) {
            return SIM_PS_OPERATION_ENABLED;
        }
        return state;
    }
    return state;
}

int sim_drive_on_nmt(sim_drive_t *d, uint8_t command)
{
    const uint8_t before = d->nmt_state;
    if (command == SIM_NMT_START) {
        d->nmt_state = SIM_NMT_STATE_OPERATIONAL;
    } else if (command == SIM_NMT_STOP) {
        d->nmt_state = SIM_NMT_STATE_STOPPED;
        d->target_torque = 0.0;
        if (d->power == SIM_PS_OPERATION_ENABLED) move_to(d, SIM_PS_QUICK_STOP_ACTIVE);
    }
    return d->nmt_state != before;
}

void sim_drive_on_command(sim_drive_t *d, uint16_t controlword, double torque)
{
    if (d->nmt_state != SIM_NMT_STATE_OPERATIONAL) {
        return; /* PDOs are only processed in NMT operational */
    }
    move_to(d, sim_cia402_next(d->power, controlword, d->controlword, SIM_QS_QUICK));
    d->controlword = controlword;
    d->periods_without_command = 0u;
    d->commands_received++;
    /* A command above the limit is refused, not clamped: a controller that asks for more than
     * the drive can give is wrong (or not the controller), and clamping would hide it. The
     * tolerance covers the wire's 1 uNm rounding of a command exactly at the limit. */
    if (torque > d->torque_limit + SIM_TORQUE_TOLERANCE || torque < -d->torque_limit - SIM_TORQUE_TOLERANCE) {
        d->target_torque = 0.0;
        sim_drive_fault(d, SIM_ERR_TORQUE_ABOVE_LIMIT, SIM_EMCY_TORQUE_LIMIT);
        return;
    }
    d->target_torque = torque > d->torque_limit ? d->torque_limit
                       : torque < -d->torque_limit ? -d->torque_limit : torque;
}

void sim_drive_on_period_end(sim_drive_t *d, int got_command)
{
    if (got_command || d->power != SIM_PS_OPERATION_ENABLED) {
        return;
    }
    d->commands_missed++;
    d->periods_without_command++;
    if (d->periods_without_command >= d->command_timeout_periods) {
        sim_drive_fault(d, SIM_ERR_COMMAND_TIMEOUT, SIM_EMCY_RPDO_TIMEOUT);
    }
}

void sim_drive_fault(sim_drive_t *d, uint8_t error_code, uint16_t emcy_code)
{
    if (d->power != SIM_PS_FAULT && d->power != SIM_PS_FAULT_REACTION) {
        sim_power_stage_fault(&d->ps, &d->power, SIM_FR_QUICK, d->quick_stop_decel, d->quick_stop_decel);
        d->error_code = error_code;
        if (d->n_emcy_pending < SIM_EMCY_QUEUE) {
            d->emcy_pending[d->n_emcy_pending++] = emcy_code;
        }
    }
}

double sim_drive_period(sim_drive_t *d, double qd, double dt)
{
    return sim_power_stage_period(&d->ps, &d->power, d->target_torque, qd, dt);
}

double sim_drive_applied_torque(const sim_drive_t *d)
{
    return d->ps.last_nm;
}
