/* The emulated servo drive: the torque path (latency, current loop, ripple) against closed forms,
 * the encoders' quantisation (joint and motor) and the velocity estimate. */
#include <math.h>

#include "check.h"
#include "sim_servo.h"

#define PI 3.14159265358979323846
#define T 1e-3

static int near(double a, double b, double tol) { return fabs(a - b) <= tol; }

static void ideal_drive_acts_at_once_and_reports_the_truth(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    CHECK(sim_servo_is_ideal(&c));
    sim_servo_t s;
    sim_servo_init(&s);
    /* a command 40 % into the period: the period's average is 0.6 of it */
    CHECK(near(sim_servo_period_torque(&c, &s, 10.0, 0.4 * T, T, 0.0), 6.0, 1e-12));
    CHECK(near(sim_servo_period_torque(&c, &s, 10.0, 0.0, T, 0.0), 10.0, 1e-12));
    double q, qd, tau;
    sim_rng_t r;
    sim_rng_seed(&r, 1);
    sim_servo_measure(&c, &s, &r, 0.123456789, -0.5, 0.123456789, -0.5, T, &q, &qd, &tau);
    CHECK(q == 0.123456789 && qd == -0.5 && tau == 10.0);
}

static void current_loop_lags_by_its_time_constant(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    c.current_loop_hz = 1000.0;
    const double tau_s = 1.0 / (2.0 * PI * 1000.0);
    sim_servo_t s;
    sim_servo_init(&s);
    const double avg = sim_servo_period_torque(&c, &s, 1.0, 0.0, T, 0.0);
    CHECK(near(avg, 1.0 - tau_s / T * (1.0 - exp(-T / tau_s)), 1e-12)); /* step response, averaged */
    CHECK(near(s.torque, 1.0 - exp(-T / tau_s), 1e-12));
    for (int k = 0; k < 20; ++k) sim_servo_period_torque(&c, &s, 1.0, 0.0, T, 0.0);
    CHECK(near(s.torque, 1.0, 1e-9)); /* settles on the command */
}

static void latency_delays_the_command(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    c.latency_s = 250e-6;
    sim_servo_t s;
    sim_servo_init(&s);
    CHECK(near(sim_servo_period_torque(&c, &s, 4.0, 0.5 * T, T, 0.0), 1.0, 1e-12)); /* acts from 0.75 T */
    sim_servo_init(&s);
    c.latency_s = 2e-3; /* past the period: from the next one */
    CHECK(near(sim_servo_period_torque(&c, &s, 4.0, 0.0, T, 0.0), 0.0, 1e-12));
    CHECK(near(sim_servo_period_torque(&c, &s, 4.0, 0.0, T, 0.0), 4.0, 1e-12));
}

static void ripple_scales_the_torque_with_position(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    c.ripple = 0.1;
    c.ripple_periods = 6.0;
    sim_servo_t s;
    sim_servo_init(&s);
    CHECK(near(sim_servo_period_torque(&c, &s, 2.0, 0.0, T, PI / 12.0), 2.2, 1e-12)); /* sin(6 pi/12) = 1 */
}

static void encoder_quantises_and_velocity_comes_from_differences(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    c.encoder_bits = 10;
    c.velocity_filter_hz = 1e9; /* no filtering to speak of: the raw difference */
    const double count = 2.0 * PI / 1024.0;
    sim_servo_t s;
    sim_servo_init(&s);
    sim_rng_t r;
    sim_rng_seed(&r, 1);
    double q, qd, tau;
    sim_servo_measure(&c, &s, &r, 10.4 * count, 0.7, 10.4 * count, 0.7, T, &q, &qd, &tau);
    CHECK(near(q, 10.0 * count, 1e-15) && qd == 0.7); /* the first sample: no difference yet */
    sim_servo_measure(&c, &s, &r, 13.6 * count, 0.7, 13.6 * count, 0.7, T, &q, &qd, &tau);
    CHECK(near(q, 14.0 * count, 1e-15));
    CHECK(near(qd, 4.0 * count / T, 1e-9));
    c.velocity_filter_hz = 100.0; /* low-passed: a step of the raw estimate moves it by 1 - e^(-2 pi f T) */
    sim_servo_init(&s);
    sim_servo_measure(&c, &s, &r, 0.0, 0.0, 0.0, 0.0, T, &q, &qd, &tau);
    sim_servo_measure(&c, &s, &r, 5.0 * count, 0.0, 5.0 * count, 0.0, T, &q, &qd, &tau);
    CHECK(near(qd, (1.0 - exp(-2.0 * PI * 100.0 * T)) * 5.0 * count / T, 1e-9));
}

static void motor_encoder_is_gear_ratio_times_finer(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    c.encoder_bits = 10;
    c.motor_encoder_bits = 10;
    c.gear_ratio = 100.0;
    c.velocity_filter_hz = 1e9;
    const double joint_count = 2.0 * PI / 1024.0, motor_count = joint_count / 100.0;
    sim_servo_t s;
    sim_servo_init(&s);
    sim_rng_t r;
    sim_rng_seed(&r, 1);
    double q, qd, tau;
    const double q0 = 10.4 * joint_count; /* 1040 motor counts */
    sim_servo_measure(&c, &s, &r, q0, 0.0, q0, 0.0, T, &q, &qd, &tau);
    CHECK(near(q, 10.0 * joint_count, 1e-15)); /* the position still from the joint encoder */
    c.velocity_source = SIM_ENCODER_MOTOR;
    sim_servo_init(&s);
    sim_servo_measure(&c, &s, &r, q0, 0.0, q0, 0.0, T, &q, &qd, &tau);
    sim_servo_measure(&c, &s, &r, q0 + 3.3 * motor_count, 0.0, q0 + 3.3 * motor_count, 0.0, T, &q, &qd, &tau);
    CHECK(near(qd, 3.0 * motor_count / T, 1e-9)); /* a move the joint encoder does not see */
    CHECK(near(q, 10.0 * joint_count, 1e-15));
    c.position_source = SIM_ENCODER_MOTOR;
    sim_servo_measure(&c, &s, &r, q0 + 3.6 * motor_count, 0.0, q0 + 3.6 * motor_count, 0.0, T, &q, &qd, &tau);
    CHECK(near(q, q0 + 4.0 * motor_count, 1e-12));
}

/* On a flexible joint the motor encoder reads the rotor, wound up ahead of the link: the joint
 * encoder the link. */
static void motor_encoder_reads_the_rotor(void)
{
    sim_servo_config_t c;
    sim_servo_config_default(&c);
    c.encoder_bits = 19;
    c.motor_encoder_bits = 17;
    c.gear_ratio = 101.0;
    c.velocity_filter_hz = 1e9;
    sim_servo_t s;
    sim_servo_init(&s);
    sim_rng_t r;
    sim_rng_seed(&r, 1);
    double q, qd, tau;
    const double link = 0.5, rotor = 0.5 + 2e-3; /* 2 mrad of wind-up: 4.2 motor turns' counts */
    const double joint_count = 2.0 * PI / 524288.0, motor_count = 2.0 * PI / (131072.0 * 101.0);
    sim_servo_measure(&c, &s, &r, link, 0.0, rotor, 0.0, T, &q, &qd, &tau);
    CHECK(near(q, floor(link / joint_count + 0.5) * joint_count, 1e-15));
    c.position_source = SIM_ENCODER_MOTOR;
    sim_servo_measure(&c, &s, &r, link, 0.0, rotor, 0.0, T, &q, &qd, &tau);
    CHECK(near(q, floor(rotor / motor_count + 0.5) * motor_count, 1e-15));
    CHECK(fabs(q - link) > 1e-3);
}

/* The velocity's noise at rest, sigma over n periods, for one drive and seed. */
static double velocity_sigma(const sim_servo_config_t *c, unsigned long long seed)
{
    sim_servo_t s;
    sim_servo_init(&s);
    sim_rng_t r;
    sim_rng_seed(&r, seed);
    double q, qd, tau, sq = 0.0;
    const int n = 20000;
    for (int i = 0; i <= n; ++i) {
        sim_servo_measure(c, &s, &r, 0.3, 0.0, 0.3, 0.0, T, &q, &qd, &tau);
        if (i > 0) sq += qd * qd;
    }
    return sqrt(sq / n);
}

static void velocity_from_the_motor_encoder_is_quieter(void)
{
    /* One count of noise on a 19-bit joint encoder, differenced at 1 kHz through 500 Hz: sigma
     * about 0.0165 rad/s. The same noise on a 17-bit motor encoder behind a 101:1 gear is 2^17 x
     * 101 / 2^19 = 25 times finer at the joint. */
    sim_servo_config_t joint;
    sim_servo_config_default(&joint);
    joint.encoder_bits = 19;
    joint.position_noise_counts = 1.0;
    joint.velocity_filter_hz = 500.0;
    sim_servo_config_t dual = joint;
    dual.motor_encoder_bits = 17;
    dual.gear_ratio = 101.0;
    dual.velocity_source = SIM_ENCODER_MOTOR;
    const double sj = velocity_sigma(&joint, 1), sd = velocity_sigma(&dual, 1);
    CHECK(sj > 0.014 && sj < 0.019);
    CHECK(sd < sj / 20.0 && sd > sj / 30.0);
    CHECK(velocity_sigma(&dual, 1) == sd); /* the seed gives the same noise */
}

static void noise_is_seeded_and_has_its_sigma(void)
{
    sim_rng_t r;
    sim_rng_seed(&r, 7);
    double sum = 0.0, sq = 0.0;
    const int n = 200000;
    for (int i = 0; i < n; ++i) {
        const double x = sim_rng_normal(&r);
        sum += x;
        sq += x * x;
    }
    CHECK(fabs(sum / n) < 0.01 && fabs(sq / n - 1.0) < 0.01);
}

int main(void)
{
    ideal_drive_acts_at_once_and_reports_the_truth();
    current_loop_lags_by_its_time_constant();
    latency_delays_the_command();
    ripple_scales_the_torque_with_position();
    encoder_quantises_and_velocity_comes_from_differences();
    motor_encoder_is_gear_ratio_times_finer();
    motor_encoder_reads_the_rotor();
    velocity_from_the_motor_encoder_is_quieter();
    noise_is_seeded_and_has_its_sigma();
    TEST_MAIN_END();
}
