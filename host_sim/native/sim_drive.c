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
}

sim_power_t sim_cia402_next(sim_power_t state, uint16_t cw, uint16_t prev_cw, int32_t quick_stop_option)
{
    if (state == SIM_PS_FAULT) {
        const int rising_reset = (cw & CW_FAULT_RESET) != 0u && (prev_cw & CW_FAULT_RESET) == 0u;
        return rising_reset ? SIM_PS_SWITCH_ON_DISABLED : state;
    }
    if ((cw & 0x0082u) == 0x0000u) { /* disable voltage (transitions 7, 9, 10, 12) */
        return SIM_PS_SWITCH_ON_DISABLED;
    }
    if (state == SIM_PS_QUICK_STOP_ACTIVE) { /* left by disable voltage, above, or enable operation (16) */
        return (cw & 0x008Fu) == 0x000Fu ? SIM_PS_OPERATION_ENABLED : state;
    }
    if ((cw & 0x0086u) == 0x0002u) { /* quick stop: this drive stops at once, torque off (7, 10, 11) */
        const int stays = state == SIM_PS_OPERATION_ENABLED && quick_stop_option >= 5 && quick_stop_option <= 8;
        return stays ? SIM_PS_QUICK_STOP_ACTIVE : SIM_PS_SWITCH_ON_DISABLED;
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
    }
    return d->nmt_state != before;
}

void sim_drive_on_command(sim_drive_t *d, uint16_t controlword, double torque)
{
    if (d->nmt_state != SIM_NMT_STATE_OPERATIONAL) {
        return; /* PDOs are only processed in NMT operational */
    }
    d->power = sim_cia402_next(d->power, controlword, d->controlword, SIM_QUICK_STOP_DISABLE);
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
    if (d->power != SIM_PS_FAULT) {
        d->power = SIM_PS_FAULT;
        d->error_code = error_code;
        if (d->n_emcy_pending < SIM_EMCY_QUEUE) {
            d->emcy_pending[d->n_emcy_pending++] = emcy_code;
        }
    }
}

double sim_drive_applied_torque(const sim_drive_t *d)
{
    const int enabled = d->power == SIM_PS_OPERATION_ENABLED && d->nmt_state == SIM_NMT_STATE_OPERATIONAL;
    return enabled ? d->target_torque : 0.0;
}
