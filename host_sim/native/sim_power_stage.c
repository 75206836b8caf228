#include "sim_power_stage.h"

#include <math.h>

#define TWO_PI 6.283185307179586
#define VELOCITY_LOOP_HZ 25.0 /* the drive's velocity loop bandwidth: well inside a 1 kHz period */
#define INTEGRAL_HZ 5.0
#define STANDSTILL_RAD_S 0.02  /* the joint stands still below this (CiA 402's 0x606F window) */
#define STANDSTILL_S 0.01      /* ... for this long at a zero reference */
#define SETTLE_MAX_S 0.2       /* a joint that will not settle is taken as stopped after this */

void sim_power_stage_init(sim_power_stage_t *ps, const sim_brake_config_t *brake, double torque_limit,
                          double joint_inertia)
{
    *ps = (sim_power_stage_t){0};
    ps->brake = *brake;
    ps->torque_limit = torque_limit;
    ps->kv = (joint_inertia > 0.0 ? joint_inertia : 0.0) * TWO_PI * VELOCITY_LOOP_HZ;
    ps->ki = TWO_PI * INTEGRAL_HZ;
    ps->brake_state = brake->holding_nm > 0.0 ? SIM_BRAKE_ENGAGED : SIM_BRAKE_RELEASED;
    ps->mode = SIM_STAGE_OFF;
}

void sim_power_stage_release_brake(sim_power_stage_t *ps)
{
    ps->brake_state = SIM_BRAKE_RELEASED;
}

static int energised_state(sim_power_t p)
{
    return p == SIM_PS_OPERATION_ENABLED || p == SIM_PS_QUICK_STOP_ACTIVE || p == SIM_PS_FAULT_REACTION;
}

static int has_brake(const sim_power_stage_t *ps)
{
    return ps->brake.holding_nm > 0.0;
}

static void open_brake(sim_power_stage_t *ps)
{
    if (ps->brake_state == SIM_BRAKE_ENGAGED) {
        ps->brake_state = SIM_BRAKE_RELEASING;
        ps->brake_timer_s = ps->brake.release_s;
    } else if (ps->brake_state == SIM_BRAKE_CLOSING) {
        ps->brake_state = SIM_BRAKE_RELEASED; /* it had not closed yet */
    }
}

/* The brake told to close: powered, the drive holds standstill meanwhile and reports `then` once it
 * has closed; unpowered, the power stage is off already. */
static void close_brake(sim_power_stage_t *ps, sim_power_t *power, sim_power_t then, int powered)
{
    if (!has_brake(ps)) {
        ps->mode = SIM_STAGE_OFF;
        *power = then;
        return;
    }
    if (ps->brake_state != SIM_BRAKE_ENGAGED && ps->brake_state != SIM_BRAKE_CLOSING) {
        ps->brake_state = SIM_BRAKE_CLOSING;
        ps->brake_timer_s = ps->brake.close_s;
    } else if (ps->brake_state == SIM_BRAKE_ENGAGED) {
        powered = 0; /* nothing to wait for */
    }
    ps->powered_close = powered;
    ps->after_close = then;
    if (powered) {
        if (ps->mode != SIM_STAGE_RAMP) ps->v_ref_pending = 2; /* standstill, from the next period's torque */
        ps->mode = SIM_STAGE_RAMP;
        ps->v_ref = 0.0;
    } else {
        ps->mode = SIM_STAGE_OFF;
        *power = then;
    }
}

static void start_ramp(sim_power_stage_t *ps, double decel, sim_power_t then, int stay)
{
    if (ps->mode != SIM_STAGE_RAMP) ps->v_ref_pending = 1; /* from the next period's velocity and torque */
    ps->mode = SIM_STAGE_RAMP;
    ps->decel = decel;
    ps->after_close = then;
    ps->stay_after_ramp = stay;
    ps->ramp_done = 0;
    ps->settle_s = 0.0;
}

void sim_power_stage_transition(sim_power_stage_t *ps, sim_power_t *power, sim_power_t next, int qs_option,
                                double slow_down, double quick)
{
    const sim_power_t cur = *power;
    if (next == cur) return;
    if (next == SIM_PS_OPERATION_ENABLED) {
        open_brake(ps);
        ps->mode = SIM_STAGE_FOLLOW;
        *power = next;
        return;
    }
    if (next == SIM_PS_QUICK_STOP_ACTIVE && energised_state(cur)) {
        if (qs_option == SIM_QS_DISABLE) {
            close_brake(ps, power, SIM_PS_SWITCH_ON_DISABLED, 0);
            return;
        }
        const int slow = qs_option == 1 || qs_option == 5;
        start_ramp(ps, slow ? slow_down : quick, SIM_PS_SWITCH_ON_DISABLED, qs_option >= 5);
        *power = next;
        return;
    }
    if (energised_state(cur) && !energised_state(next)) {
        close_brake(ps, power, next, 1);
        return;
    }
    *power = next;
}

void sim_power_stage_fault(sim_power_stage_t *ps, sim_power_t *power, int fr_option, double slow_down, double quick)
{
    if (*power == SIM_PS_FAULT || *power == SIM_PS_FAULT_REACTION) return;
    if (!energised_state(*power)) {
        *power = SIM_PS_FAULT;
        return;
    }
    if (fr_option == SIM_FR_DISABLE) {
        close_brake(ps, power, SIM_PS_FAULT, 0);
        return;
    }
    start_ramp(ps, fr_option == SIM_FR_SLOW_DOWN ? slow_down : quick, SIM_PS_FAULT, 0);
    *power = SIM_PS_FAULT_REACTION;
}

void sim_power_stage_power_lost(sim_power_stage_t *ps, sim_power_t *power)
{
    (void)power;
    if (ps->brake_state == SIM_BRAKE_RELEASED || ps->brake_state == SIM_BRAKE_RELEASING) {
        ps->brake_state = SIM_BRAKE_CLOSING;
        ps->brake_timer_s = ps->brake.close_s;
    }
    ps->powered_close = 0;
    ps->mode = SIM_STAGE_OFF;
    ps->last_nm = 0.0;
}

static double clamp(double x, double lim)
{
    return x > lim ? lim : x < -lim ? -lim : x;
}

/* The release or closing delay runs on by one period (the brake as it was acted through it). */
static void brake_delay(sim_power_stage_t *ps, sim_power_t *power, double dt)
{
    if (ps->brake_state != SIM_BRAKE_RELEASING && ps->brake_state != SIM_BRAKE_CLOSING) return;
    ps->brake_timer_s -= dt;
    if (ps->brake_timer_s > 1e-12) return;
    const int closed = ps->brake_state == SIM_BRAKE_CLOSING;
    ps->brake_state = closed ? SIM_BRAKE_ENGAGED : SIM_BRAKE_RELEASED;
    if (closed && ps->powered_close) { /* closed: now the power stage goes off */
        ps->powered_close = 0;
        ps->mode = SIM_STAGE_OFF;
        *power = ps->after_close;
    }
}

double sim_power_stage_period(sim_power_stage_t *ps, sim_power_t *power, double target_nm, double qd, double dt)
{
    const sim_brake_state_t brake_before = ps->brake_state;
    double tau = 0.0;
    if (ps->mode == SIM_STAGE_FOLLOW) {
        tau = target_nm;
    } else if (ps->mode == SIM_STAGE_RAMP) {
        if (ps->v_ref_pending) { /* bumpless: the loop takes over the torque being applied */
            ps->v_ref = ps->v_ref_pending == 1 ? qd : 0.0;
            ps->integ = ps->last_nm;
            ps->v_ref_pending = 0;
        }
        const double step = ps->decel > 0.0 ? ps->decel * dt : fabs(ps->v_ref);
        ps->v_ref = fabs(ps->v_ref) <= step ? 0.0 : ps->v_ref - copysign(step, ps->v_ref);
        const double err = ps->v_ref - qd;
        tau = clamp(ps->integ + ps->kv * err, ps->torque_limit);
        ps->integ = clamp(ps->integ + ps->kv * ps->ki * err * dt, ps->torque_limit);
        if (ps->v_ref == 0.0 && !ps->ramp_done && ps->brake_state != SIM_BRAKE_CLOSING) {
            ps->settle_s += dt;
            if ((fabs(qd) < STANDSTILL_RAD_S && ps->settle_s >= STANDSTILL_S) || ps->settle_s >= SETTLE_MAX_S) {
                ps->ramp_done = 1;
                if (!ps->stay_after_ramp) close_brake(ps, power, ps->after_close, 1);
            }
        }
    }
    ps->last_nm = tau;
    if (ps->brake_state == brake_before) brake_delay(ps, power, dt); /* a delay begun this period runs from the next */
    return tau;
}

double sim_power_stage_brake_nm(const sim_power_stage_t *ps)
{
    const int holds = ps->brake_state == SIM_BRAKE_ENGAGED || ps->brake_state == SIM_BRAKE_RELEASING;
    return holds ? ps->brake.holding_nm : 0.0;
}

int sim_power_stage_energised(const sim_power_stage_t *ps)
{
    return ps->mode != SIM_STAGE_OFF;
}
