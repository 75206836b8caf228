/* What a real servo drive puts between the controller and the joint, emulated per drive:
 *
 * - sensing: an absolute encoder of 2^bits counts per joint turn (quantised position, with
 *   Gaussian noise in counts before quantisation), optionally a second encoder on the motor,
 *   2^motor_bits counts per motor turn through the gear of gear_ratio (so gear_ratio times finer
 *   at the joint; on a flexible joint it reads the rotor, not the link), a velocity the drive estimates from one encoder's differences and
 *   low-passes (first order, exact discretisation), and the measured torque with Gaussian noise;
 *   which encoder reports the position and which feeds the velocity is configured;
 * - actuation: a transport latency from the command's arrival to the current loop, and the
 *   current (torque) loop as a first-order lag of the stated bandwidth; optional torque ripple
 *   (cogging), a relative amplitude at a number of periods per joint turn.
 *
 * Every feature is off at its zero value (the ideal drive). The physics advances one step per
 * period under the time average of the actual torque, which is computed exactly for the
 * piecewise-constant current-loop input. Noise comes from its own seeded stream: a seed gives the
 * same run. */
#ifndef ARM_SIM_SERVO_H
#define ARM_SIM_SERVO_H

#include "sim_rng.h"

enum { SIM_ENCODER_JOINT = 0, SIM_ENCODER_MOTOR = 1 };

typedef struct {
    int encoder_bits;              /* counts per turn = 2^bits; 0: the true position */
    double position_noise_counts;  /* sigma, in each encoder's own counts (needs encoder_bits) */
    int motor_encoder_bits;        /* counts per motor turn = 2^bits; 0: no motor encoder */
    double gear_ratio;             /* motor turns per joint turn (needs motor_encoder_bits) */
    int position_source;           /* SIM_ENCODER_JOINT or _MOTOR: the position reported */
    int velocity_source;           /* the encoder whose differences give the velocity */
    double velocity_filter_hz;     /* velocity from encoder differences, low-passed here; 0: the true velocity */
    double torque_noise_nm;        /* sigma of the torque the drive reports */
    double current_loop_hz;        /* first-order torque lag of this bandwidth; 0: immediate */
    double latency_s;              /* command arrival -> current loop input */
    double ripple;                 /* relative torque ripple amplitude; 0: none */
    double ripple_periods;         /* ripple periods per joint turn */
} sim_servo_config_t;

typedef struct {
    double torque;       /* the current loop's output at the start of the period */
    double input;        /* its input (the last command) */
    double q_prev;       /* the velocity source's last position, for the velocity estimate */
    double v_filtered;
    int primed;          /* q_prev and v_filtered hold values */
} sim_servo_t;

void sim_servo_config_default(sim_servo_config_t *c);
int sim_servo_is_ideal(const sim_servo_config_t *c);
void sim_servo_init(sim_servo_t *s);
/* The torque the joint feels over one period of length T: the previous command acts until
 * switch_s (+ latency) into the period, then `command`; through the current loop; times the
 * ripple at q. Advances the loop's state to the period's end. */
double sim_servo_period_torque(const sim_servo_config_t *c, sim_servo_t *s, double command, double switch_s,
                               double period_s, double q);
/* What the drive reports at a SYNC: position, velocity, torque, from the true link angle q and
 * speed qd, the motor's qm and qmd (in joint units: the rotor's on a flexible joint, else q and
 * qd) and the torque acting (the current loop's output). */
void sim_servo_measure(const sim_servo_config_t *c, sim_servo_t *s, sim_rng_t *noise, double q, double qd,
                       double qm, double qmd, double period_s, double *q_out, double *qd_out, double *tau_out);
/* A standard normal value (Box-Muller on the stream's doubles). */
double sim_rng_normal(sim_rng_t *r);

#endif
