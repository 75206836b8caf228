/* Our inverse dynamics on the agreement check's states, printed with the model it ran, so
 * tests/python/test_bench_rnea.py can hand both to Pinocchio's Python bindings (the same library
 * `armctl bench step` compiles against) without compiling Pinocchio's headers. Every float is
 * printed with 9 significant digits: it reads back as the same float.
 *   gravity gx gy gz
 *   link pos[3] rot[9] axis[3] mass com[3] inertia[9] armature damping   (one a joint, in order)
 *   state q[n] qd[n] qdd[n] tau[n] tau_kernel[n]   (tau: arm_rnea; tau_kernel: arm_rnea_kernel) */
#include <stdio.h>

#include "arm/rnea.h"
#include "arm_rnea_kernel.h"
#include "arm_robot_model_data.h"
#include "rnea_states.h"

static void put(const float *v, int n)
{
    for (int i = 0; i < n; ++i) {
        printf(" %.9g", (double)v[i]);
    }
}

int main(void)
{
    const arm_robot_model_t *m = &ARM_ROBOT_MODEL;
    printf("gravity");
    put(m->gravity, 3);
    printf("\n");
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const arm_link_t *l = &m->link[i];
        printf("link");
        put(l->pos, 3);
        put(&l->rot[0][0], 9);
        put(l->axis, 3);
        put(&l->mass, 1);
        put(l->com, 3);
        put(&l->inertia[0][0], 9);
        put(&l->armature, 1);
        put(&l->damping, 1);
        printf("\n");
    }
    for (int k = 0; k < ARM_RNEA_CHECK_STATES; ++k) {
        float q[ARM_N_JOINTS], qd[ARM_N_JOINTS], qdd[ARM_N_JOINTS], tau[ARM_N_JOINTS], tau_k[ARM_N_JOINTS];
        arm_rnea_state(ARM_RNEA_CHECK_STRIDE * k, q, qd, qdd);
        arm_rnea(m, q, qd, qdd, tau);
        arm_rnea_kernel(q, qd, qdd, tau_k);
        printf("state");
        put(q, ARM_N_JOINTS);
        put(qd, ARM_N_JOINTS);
        put(qdd, ARM_N_JOINTS);
        put(tau, ARM_N_JOINTS);
        put(tau_k, ARM_N_JOINTS);
        printf("\n");
    }
    return 0;
}
