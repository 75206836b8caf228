/* The arm with flexible joints (the build's plant.xml, gen/drivetrain.py) and the payload:
 * - it starts at rest: every gear wound up against gravity, the rotor ahead of its link by
 *   g(q) / K, so motor torques equal to gravity's hold the arm where it is;
 * - the motor encoder's angle is the rotor's, and a softer gear winds up further;
 * - a payload at the flange adds exactly its weight's torques, m J_p^T g, where the model's site
 *   'payload' is; a drawn one lies in its range and differs between seeds;
 * - w from the plant's own step equals w from a forward pass of the nominal model, to rounding,
 *   under the paper's uncertainty, friction and torques beyond the range. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "sim_arm.h"

static int open_with(sim_arm_t *a, const char *plant, double scale, double lo, double hi, unsigned long long seed)
{
    sim_uncertainty_t u;
    sim_uncertainty_default(&u);
    u.gear_stiffness_scale = scale;
    u.payload_kg[0] = lo;
    u.payload_kg[1] = hi;
    u.seed = seed;
    char err[600];
    if (sim_arm_open(a, ARM_TEST_MODEL, plant, "home", 1, &u, err, sizeof(err)) != 0) {
        CHECK_MSG(0, "%s", err);
        return -1;
    }
    return 0;
}

/* The gear wind-up of joint j: rotor minus link (0 on a rigid joint). */
static double wind_up(const sim_arm_t *a, int j)
{
    return sim_arm_motor_q(a, j) - a->data->qpos[j];
}

static void starts_at_rest_and_gravity_holds_it(void)
{
    sim_arm_t a;
    if (open_with(&a, ARM_TEST_PLANT, 1.0, 0.0, 0.0, 1) != 0) return;
    CHECK_MSG(a.flexible >= 1, "the bundled arm has flexible joints (%d)", a.flexible);
    double hold[SIM_MAX_JOINTS], q0[SIM_MAX_JOINTS], w[SIM_MAX_JOINTS];
    for (int j = 0; j < a.n; ++j) {
        hold[j] = a.data->qfrc_bias[j]; /* gravity at rest, on the link: what the motor must give */
        q0[j] = a.data->qpos[j];
    }
    int wound = 0;
    for (int j = 0; j < a.n; ++j) wound += fabs(wind_up(&a, j)) > 1e-6;
    CHECK_MSG(wound >= 2, "the gears carrying the arm are wound up (%d)", wound);
    double drift = 0.0;
    for (int k = 0; k < 500; ++k) {
        CHECK(sim_arm_step(&a, hold, NULL, w) == 0);
        for (int j = 0; j < a.n; ++j) drift = fmax(drift, fabs(a.data->qpos[j] - q0[j]));
    }
    CHECK_MSG(drift < 1e-5, "held by gravity's torques, the links stayed within %.3g rad", drift);
    printf("flexible arm (%d flexible joints) held at rest: links within %.2g rad over 0.5 s\n", a.flexible, drift);
    sim_arm_close(&a);
}

static void softer_gears_wind_up_further(void)
{
    sim_arm_t stiff, soft;
    if (open_with(&stiff, ARM_TEST_PLANT, 1.2, 0.0, 0.0, 1) != 0 || open_with(&soft, ARM_TEST_PLANT, 0.8, 0.0, 0.0, 1) != 0) {
        return;
    }
    int compared = 0;
    for (int j = 0; j < stiff.n; ++j) {
        if (stiff.motor_dof[j] == j || fabs(wind_up(&stiff, j)) < 1e-6) continue;
        const double ratio = wind_up(&soft, j) / wind_up(&stiff, j);
        CHECK_MSG(fabs(ratio - 1.5) < 1e-6, "joint %d: 0.8x the stiffness winds up 1.5x as far, got %.6f", j + 1, ratio);
        compared++;
    }
    CHECK(compared >= 1);
    sim_arm_close(&stiff);
    sim_arm_close(&soft);
}

static void rigid_arm_has_its_motors_on_its_links(void)
{
    sim_arm_t a;
    if (open_with(&a, NULL, 1.0, 0.0, 0.0, 1) != 0) return;
    CHECK(a.flexible == 0);
    for (int j = 0; j < a.n; ++j) CHECK(a.motor_dof[j] == j && wind_up(&a, j) == 0.0);
    sim_uncertainty_t u;
    sim_uncertainty_default(&u);
    u.gear_stiffness_scale = 0.9;
    sim_arm_t b;
    char err[600];
    CHECK_MSG(sim_arm_open(&b, ARM_TEST_MODEL, NULL, "home", 1, &u, err, sizeof(err)) != 0 &&
                  strstr(err, "--gear-stiffness-scale") != NULL,
              "a stiffness scale without flexible joints is refused, naming the option: %s", err);
    sim_arm_close(&a);
}

static void payload_adds_its_weight(void)
{
    const double kg = 5.0;
    sim_arm_t bare, loaded;
    if (open_with(&bare, NULL, 1.0, 0.0, 0.0, 1) != 0 || open_with(&loaded, NULL, 1.0, kg, kg, 1) != 0) return;
    CHECK(loaded.payload_kg == kg && loaded.nominal_differs && !loaded.w_from_true_arm);
    const int site = mj_name2id(bare.model, mjOBJ_SITE, "payload");
    CHECK_MSG(site >= 0, "arm.xml has the site 'payload'");
    if (site < 0) return;
    double jacp[3 * SIM_MAX_JOINTS];
    mj_jacSite(bare.model, bare.data, jacp, NULL, site);
    double worst = 0.0;
    for (int j = 0; j < bare.n; ++j) {
        const double want = -kg * bare.model->opt.gravity[2] * jacp[2 * bare.n + j]; /* J_p^T (0, 0, m g) */
        const double got = loaded.data->qfrc_bias[j] - bare.data->qfrc_bias[j];
        worst = fmax(worst, fabs(got - want) / (1.0 + fabs(want)));
    }
    CHECK_MSG(worst < 1e-9, "the payload's torques at rest are m J_p^T g (worst relative error %.3g)", worst);
    sim_arm_t s1, s2;
    if (open_with(&s1, NULL, 1.0, 0.0, kg, 1) != 0 || open_with(&s2, NULL, 1.0, 0.0, kg, 2) != 0) return;
    CHECK(s1.payload_kg >= 0.0 && s1.payload_kg <= kg && s2.payload_kg >= 0.0 && s2.payload_kg <= kg);
    CHECK_MSG(s1.payload_kg != s2.payload_kg, "two seeds draw two payloads (%g, %g)", s1.payload_kg, s2.payload_kg);
    printf("payload %g kg adds m J_p^T g to within %.2g; seeds 1 and 2 drew %.3f and %.3f kg\n", kg, worst,
           s1.payload_kg, s2.payload_kg);
    sim_arm_close(&bare);
    sim_arm_close(&loaded);
    sim_arm_close(&s1);
    sim_arm_close(&s2);
}

static void w_from_the_plant_is_the_nominal_forward_pass(void)
{
    sim_uncertainty_t u;
    sim_uncertainty_default(&u);
    u.paper_ratio = 0.3;
    for (int j = 0; j < SIM_MAX_JOINTS; ++j) {
        u.viscous[j] = 0.5;
        u.coulomb[j] = 2.0;
    }
    sim_arm_t fast, slow;
    char err[600];
    if (sim_arm_open(&fast, ARM_TEST_MODEL, ARM_TEST_PLANT, "home", 1, &u, err, sizeof(err)) != 0 ||
        sim_arm_open(&slow, ARM_TEST_MODEL, ARM_TEST_PLANT, "home", 1, &u, err, sizeof(err)) != 0) {
        CHECK_MSG(0, "%s", err);
        return;
    }
    CHECK_MSG(fast.w_from_plant, "the bundled arm's plant qualifies");
    slow.w_from_plant = 0;
    double worst = 0.0;
    int same = 1;
    for (int k = 0; k < 3000 && same; ++k) {
        double tau[SIM_MAX_JOINTS], cmd[SIM_MAX_JOINTS], wf[SIM_MAX_JOINTS], ws[SIM_MAX_JOINTS];
        for (int j = 0; j < fast.n; ++j) {
            tau[j] = 1.2 * fast.torque_limit[j] * sin(2.0 * 3.14159265358979 * (0.7 + 0.3 * j) * k * fast.period);
            cmd[j] = 0.9 * tau[j];
        }
        CHECK(sim_arm_step(&fast, tau, cmd, wf) == sim_arm_step(&slow, tau, cmd, ws));
        same = memcmp(fast.data->qpos, slow.data->qpos, (size_t)fast.model->nq * sizeof(double)) == 0;
        for (int j = 0; j < fast.n; ++j) worst = fmax(worst, fabs(wf[j] - ws[j]) / (1.0 + fabs(ws[j])));
    }
    CHECK_MSG(same, "the plant moved differently");
    CHECK_MSG(worst < 1e-9, "w differs by %.3g (relative)", worst);
    printf("flexible plant: w from its own step agrees to %.2g (relative) over 3 s\n", worst);
    sim_arm_close(&fast);
    sim_arm_close(&slow);
}

int main(void)
{
    starts_at_rest_and_gravity_holds_it();
    softer_gears_wind_up_further();
    rigid_arm_has_its_motors_on_its_links();
    payload_adds_its_weight();
    w_from_the_plant_is_the_nominal_forward_pass();
    TEST_MAIN_END();
}
