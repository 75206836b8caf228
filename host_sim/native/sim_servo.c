/* The emulated servo drive's sensing and torque path (sim_servo.h). */
#include "sim_servo.h"

#include "arm_params.h"

#include <math.h>
#include <string.h>

#define SIM_PI 3.14159265358979323846

void sim_servo_config_default(sim_servo_config_t *c)
{
    memset(c, 0, sizeof(*c));
    c->ripple_periods = ARM_P_SIMULATOR_RIPPLE_PERIODS_DEFAULT;
}

int sim_servo_is_ideal(const sim_servo_config_t *c)
{
    return c->encoder_bits == 0 && c->motor_encoder_bits == 0 && c->velocity_filter_hz == 0.0 && c->torque_noise_nm == 0.0 &&
           c->current_loop_hz == 0.0 && c->latency_s == 0.0 && c->ripple == 0.0;
}

void sim_servo_init(sim_servo_t *s)
{
    memset(s, 0, sizeof(*s));
}

/* The lag's output over [0, len) from x0 under a constant input u: its integral, and x at len. */
static double lag_segment(double tau_s, double u, double len, double *x)
{
    if (len <= 0.0) return 0.0;
    if (tau_s <= 0.0) {
        *x = u;
        return u * len;
    }
    const double decay = exp(-len / tau_s);
    const double integral = u * len + (*x - u) * tau_s * (1.0 - decay);
    *x = u + (*x - u) * decay;
    return integral;
}

double sim_servo_period_torque(const sim_servo_config_t *c, sim_servo_t *s, double command, double switch_s,
                               double period_s, double q)
{
    const double tau_s = c->current_loop_hz > 0.0 ? 1.0 / (2.0 * SIM_PI * c->current_loop_hz) : 0.0;
    const double t_switch = switch_s + c->latency_s;
    double x = s->torque;
    double integral;
    if (t_switch >= period_s) {
        /* Arrives at the current loop after this period: it acts from the next one (the part of
         * the latency past the period's end is not carried over). */
        integral = lag_segment(tau_s, s->input, period_s, &x);
    } else {
        integral = lag_segment(tau_s, s->input, t_switch, &x);
        integral += lag_segment(tau_s, command, period_s - t_switch, &x);
    }
    s->input = command;
    s->torque = x;
    double avg = integral / period_s;
    if (c->ripple != 0.0) avg *= 1.0 + c->ripple * sin(c->ripple_periods * q);
    return avg;
}

double sim_rng_normal(sim_rng_t *r)
{
    double u1 = sim_rng_double(r);
    const double u2 = sim_rng_double(r);
    if (u1 < 1e-300) u1 = 1e-300;
    return sqrt(-2.0 * log(u1)) * cos(2.0 * SIM_PI * u2);
}

/* One encoder's reading of the joint angle q: 2^bits counts per turn of a shaft turning `ratio`
 * times the joint, the noise (sigma in counts) before quantisation, in joint radians. */
static double encoder_read(int bits, double ratio, double noise_counts, sim_rng_t *noise, double q)
{
    const double count = 2.0 * SIM_PI / (ldexp(1.0, bits) * ratio);
    double counts = q / count;
    if (noise_counts > 0.0) counts += noise_counts * sim_rng_normal(noise);
    return floor(counts + 0.5) * count;
}

void sim_servo_measure(const sim_servo_config_t *c, sim_servo_t *s, sim_rng_t *noise, double q, double qd,
                       double qm_true, double qmd_true, double period_s, double *q_out, double *qd_out,
                       double *tau_out)
{
    const double qj = c->encoder_bits > 0 ? encoder_read(c->encoder_bits, 1.0, c->position_noise_counts, noise, q) : q;
    /* The motor encoder counts turns from power-up, where the joint encoder gave the absolute
     * position: modelled as referenced to the rotor's angle then (no backlash; the gear's wind-up
     * is the rotor's own, on a flexible joint). */
    const double qm = c->motor_encoder_bits > 0
                          ? encoder_read(c->motor_encoder_bits, c->gear_ratio, c->position_noise_counts, noise, qm_true)
                          : qm_true;
    const double qv = c->velocity_source == SIM_ENCODER_MOTOR ? qm : qj;
    /* the true velocity (no filter): the encoder's shaft's */
    double vm = c->velocity_source == SIM_ENCODER_MOTOR ? qmd_true : qd;
    if (c->velocity_filter_hz > 0.0) {
        if (!s->primed) {
            s->v_filtered = qd; /* the drive has been running before the controller asks */
        } else {
            const double raw = (qv - s->q_prev) / period_s;
            const double a = 1.0 - exp(-2.0 * SIM_PI * c->velocity_filter_hz * period_s);
            s->v_filtered += a * (raw - s->v_filtered);
        }
        vm = s->v_filtered;
    }
    s->q_prev = qv;
    s->primed = 1;
    double tm = s->torque;
    if (c->torque_noise_nm > 0.0) tm += c->torque_noise_nm * sim_rng_normal(noise);
    *q_out = c->position_source == SIM_ENCODER_MOTOR ? qm : qj;
    *qd_out = vm;
    *tau_out = tm;
}
