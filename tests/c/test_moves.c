/* The core's task references (arm/reference.h): the bounded move every task starts with, and the
 * trajectory through knots (cubic Hermite) a trajectory file becomes. */
#include <math.h>
#include <string.h>

#include "arm/reference.h"
#include "check.h"

#define N ARM_N_JOINTS

static void move_keeps_its_bounds_and_arrives_together(void)
{
    float from[N], to[N];
    for (int j = 0; j < N; ++j) {
        from[j] = 0.1f * (float)j;
        to[j] = from[j] + (j == 1 ? 2.0f : -0.3f * (float)j); /* joint 1 goes furthest: it sets the pace */
    }
    arm_move_t m;
    const float v = 0.5f, a = 1.0f;
    CHECK(arm_move_plan(&m, from, to, v, a) == 0);
    CHECK(fabsf(m.t_acc - v / a) < 1e-6f && fabsf(m.t_total - (2.0f / v + v / a)) < 1e-5f); /* cruises */
    float q[N], qd[N], qdd[N], prev[N];
    arm_move_eval(&m, 0.0f, prev, qd, qdd);
    for (int j = 0; j < N; ++j) CHECK(prev[j] == from[j] && qd[j] == 0.0f);
    const float dt = 1e-3f;
    float vmax = 0.0f, amax = 0.0f, worst_step = 0.0f;
    for (float t = dt; t <= m.t_total + 0.01f; t += dt) {
        arm_move_eval(&m, t, q, qd, qdd);
        for (int j = 0; j < N; ++j) {
            vmax = fabsf(qd[j]) > vmax ? fabsf(qd[j]) : vmax;
            amax = fabsf(qdd[j]) > amax ? fabsf(qdd[j]) : amax;
            /* the position follows its velocity: no jump */
            const float step = fabsf(q[j] - prev[j] - qd[j] * dt);
            worst_step = step > worst_step ? step : worst_step;
            prev[j] = q[j];
        }
    }
    CHECK_MSG(vmax <= v * 1.0001f && vmax > 0.99f * v, "vmax %g", (double)vmax);
    CHECK_MSG(amax <= a * 1.0001f, "amax %g", (double)amax);
    CHECK_MSG(worst_step < 1e-3f, "position step %g", (double)worst_step);
    arm_move_eval(&m, m.t_total, q, qd, qdd);
    for (int j = 0; j < N; ++j) CHECK(q[j] == to[j] && qd[j] == 0.0f && qdd[j] == 0.0f);
    /* the middle of the move: every joint the same fraction of its way */
    arm_move_eval(&m, 0.5f * m.t_total, q, qd, qdd);
    for (int j = 0; j < N; ++j) {
        if (to[j] != from[j]) CHECK(fabsf((q[j] - from[j]) / (to[j] - from[j]) - 0.5f) < 1e-4f);
    }
    /* too short to reach v: accelerate, then brake */
    to[1] = from[1] + 0.1f;
    for (int j = 0; j < N; ++j) {
        if (j != 1) to[j] = from[j];
    }
    CHECK(arm_move_plan(&m, from, to, v, a) == 0);
    CHECK(fabsf(m.t_total - 2.0f * sqrtf(0.1f / a)) < 1e-5f);
    /* already there; bad bounds */
    CHECK(arm_move_plan(&m, from, from, v, a) == 0 && m.t_total == 0.0f);
    arm_move_eval(&m, 1.0f, q, qd, qdd);
    CHECK(q[2] == from[2] && qd[2] == 0.0f);
    CHECK(arm_move_plan(&m, from, to, 0.0f, a) == -1 && arm_move_plan(&m, from, to, v, NAN) == -1);
}

/* A cubic in t is reproduced exactly by Hermite segments given its values and slopes at the knots. */
static float cubic(float t, int j) { return (0.3f + 0.1f * (float)j) * t * t * t - 0.5f * t * t + 0.2f * t + (float)j; }
static float cubic_d(float t, int j) { return 3.0f * (0.3f + 0.1f * (float)j) * t * t - t + 0.2f; }
static float cubic_dd(float t, int j) { return 6.0f * (0.3f + 0.1f * (float)j) * t - 1.0f; }

static void trajectory_is_exact_on_a_cubic_and_rests_outside(void)
{
    static float t[5] = {0.0f, 0.3f, 0.7f, 1.2f, 2.0f};
    static float q[5 * N], qd[5 * N];
    for (int k = 0; k < 5; ++k) {
        for (int j = 0; j < N; ++j) {
            q[k * N + j] = cubic(t[k], j);
            qd[k * N + j] = cubic_d(t[k], j);
        }
    }
    arm_traj_t tr;
    CHECK(arm_traj_init(&tr, t, q, qd, 5u) == 0 && fabsf(arm_traj_duration(&tr) - 2.0f) < 1e-7f);
    float a[N], ad[N], add[N];
    float worst = 0.0f;
    for (float s = 0.01f; s < 2.0f; s += 0.013f) {
        arm_traj_eval(&tr, s, a, ad, add);
        for (int j = 0; j < N; ++j) {
            const float e = fabsf(a[j] - cubic(s, j)) + fabsf(ad[j] - cubic_d(s, j)) + 0.1f * fabsf(add[j] - cubic_dd(s, j));
            worst = e > worst ? e : worst;
        }
    }
    CHECK_MSG(worst < 2e-4f, "worst %g", (double)worst);
    arm_traj_eval(&tr, 5.0f, a, ad, add); /* after the end: the last knot, at rest */
    for (int j = 0; j < N; ++j) CHECK(a[j] == q[4 * N + j] && ad[j] == 0.0f && add[j] == 0.0f);
    arm_traj_eval(&tr, 0.5f, a, ad, add); /* an earlier time restarts the cursor */
    CHECK(fabsf(a[0] - cubic(0.5f, 0)) < 1e-4f);
    arm_traj_eval(&tr, -1.0f, a, ad, add);
    CHECK(a[3] == q[3]);
    static float bad_t[3] = {0.0f, 0.5f, 0.5f};
    CHECK(arm_traj_init(&tr, bad_t, q, qd, 3u) == -1);
    static float late_t[2] = {0.1f, 0.5f};
    CHECK(arm_traj_init(&tr, late_t, q, qd, 2u) == -1 && arm_traj_init(&tr, t, q, qd, 1u) == -1);
}

int main(void)
{
    move_keeps_its_bounds_and_arrives_together();
    trajectory_is_exact_on_a_cubic_and_rests_outside();
    TEST_MAIN_END();
}
