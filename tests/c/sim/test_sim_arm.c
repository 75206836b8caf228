/* The simulated arm's w (nominal minus true acceleration) from the true arm's own step equals w
 * from a forward pass of the nominal model, to rounding, and the arm moves bit for bit the same:
 * with friction that sticks (frictionloss constraints), the paper-style uncertainty, torques
 * beyond the actuators' range and a commanded torque that is not the applied one. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "sim_arm.h"

#define PERIODS 3000

typedef struct {
    const char *name;
    double paper_ratio, viscous, coulomb, overdrive;
} case_t;

static int open_arm(sim_arm_t *a, const case_t *c)
{
    sim_uncertainty_t u;
    sim_uncertainty_default(&u);
    u.paper_ratio = c->paper_ratio;
    for (int j = 0; j < SIM_MAX_JOINTS; ++j) {
        u.viscous[j] = c->viscous;
        u.coulomb[j] = c->coulomb;
    }
    char err[600];
    if (sim_arm_open(a, ARM_TEST_MODEL, NULL, "home", 1, &u, err, sizeof(err)) != 0) {
        CHECK_MSG(0, "%s", err);
        return -1;
    }
    return 0;
}

static void both_ways_agree(const case_t *c)
{
    sim_arm_t fast, slow;
    if (open_arm(&fast, c) != 0 || open_arm(&slow, c) != 0) return;
    CHECK_MSG(fast.w_from_true_arm, "%s: the bundled arm qualifies", c->name);
    slow.w_from_true_arm = 0;
    const int n = fast.n;
    double worst = 0.0;
    int moved_same = 1;
    for (int k = 0; k < PERIODS && moved_same; ++k) {
        double tau[SIM_MAX_JOINTS], cmd[SIM_MAX_JOINTS], wf[SIM_MAX_JOINTS], ws[SIM_MAX_JOINTS];
        for (int j = 0; j < n; ++j) {
            const double t = k * fast.period;
            tau[j] = c->overdrive * fast.torque_limit[j] * sin(2.0 * 3.14159265358979 * (0.7 + 0.3 * j) * t);
            cmd[j] = 0.9 * tau[j] + 0.1 * fast.torque_limit[j];
        }
        const int bf = sim_arm_step(&fast, tau, cmd, wf);
        const int bs = sim_arm_step(&slow, tau, cmd, ws);
        CHECK(bf == bs);
        moved_same = memcmp(fast.data->qpos, slow.data->qpos, (size_t)fast.model->nq * sizeof(double)) == 0 &&
                     memcmp(fast.data->qvel, slow.data->qvel, (size_t)n * sizeof(double)) == 0;
        for (int j = 0; j < n; ++j) {
            const double e = fabs(wf[j] - ws[j]) / (1.0 + fabs(ws[j]));
            worst = e > worst ? e : worst;
        }
    }
    CHECK_MSG(moved_same, "%s: the arm moved differently", c->name);
    CHECK_MSG(worst < 1e-9, "%s: w differs by %.3g (relative)", c->name, worst);
    printf("%s: w agrees to %.3g (relative), the arm moved bit for bit the same\n", c->name, worst);
    sim_arm_close(&fast);
    sim_arm_close(&slow);
}

static void parametric_error_takes_the_nominal_forward_pass(void)
{
    sim_uncertainty_t u;
    sim_uncertainty_default(&u);
    u.mass_error = 0.1;
    sim_arm_t a;
    char err[600];
    CHECK(sim_arm_open(&a, ARM_TEST_MODEL, NULL, "home", 1, &u, err, sizeof(err)) == 0);
    CHECK(!a.w_from_true_arm); /* other links: the nominal model's M is not the true one's */
    sim_arm_close(&a);
}

int main(void)
{
    const case_t cases[] = {
        {"ideal", 0.0, 0.0, 0.0, 0.3},
        {"friction that sticks, paper-style", 0.3, 0.5, 3.0, 0.3},
        {"torques beyond the range", 0.0, 0.2, 0.5, 1.8},
    };
    for (unsigned i = 0; i < sizeof(cases) / sizeof(cases[0]); ++i) both_ways_agree(&cases[i]);
    parametric_error_takes_the_nominal_forward_pass();
    TEST_MAIN_END();
}
