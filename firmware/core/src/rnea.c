#include "arm/rnea.h"

#include <math.h>

#include "arm/vec3.h"

/* Rotation of a body relative to its parent: fixed part times the joint's rotation about axis. */
static void joint_rotation(const arm_link_t *l, float q, float r[3][3])
{
    /* Rodrigues: Rj = I cos q + sin q [a]x + (1 - cos q) a a^T */
    const float c = cosf(q);
    const float s = sinf(q);
    const float v = 1.0f - c;
    const float *a = l->axis;
    const float rj[3][3] = {
        {c + a[0] * a[0] * v, a[0] * a[1] * v - a[2] * s, a[0] * a[2] * v + a[1] * s},
        {a[1] * a[0] * v + a[2] * s, c + a[1] * a[1] * v, a[1] * a[2] * v - a[0] * s},
        {a[2] * a[0] * v - a[1] * s, a[2] * a[1] * v + a[0] * s, c + a[2] * a[2] * v},
    };
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            r[i][j] = l->rot[i][0] * rj[0][j] + l->rot[i][1] * rj[1][j] + l->rot[i][2] * rj[2][j];
        }
    }
}

void arm_rnea(const arm_robot_model_t *model, const float q[ARM_N_JOINTS],
              const float qd[ARM_N_JOINTS], const float qdd[ARM_N_JOINTS],
              float tau[ARM_N_JOINTS])
{
    float rot[ARM_N_JOINTS][3][3];   /* parent -> body i */
    float force[ARM_N_JOINTS][3];    /* net force on link i at its COM, body frame */
    float moment[ARM_N_JOINTS][3];   /* net moment on link i about its COM, body frame */

    /* Forward pass: base at rest; gravity enters as an upward acceleration of the base. */
    float w[3] = {0.0f, 0.0f, 0.0f};
    float dw[3] = {0.0f, 0.0f, 0.0f};
    float acc[3] = {-model->gravity[0], -model->gravity[1], -model->gravity[2]};
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const arm_link_t *l = &model->link[i];
        joint_rotation(l, q[i], rot[i]);

        /* Acceleration of this body's origin, expressed in the parent frame first. */
        float t1[3], t2[3], a_parent[3];
        arm_v3_cross(dw, l->pos, t1);
        arm_v3_cross(w, l->pos, t2);
        arm_v3_cross(w, t2, t2);
        for (int k = 0; k < 3; ++k) {
            a_parent[k] = acc[k] + t1[k] + t2[k];
        }
        arm_m3_tmul(rot[i], a_parent, acc);

        float w_in[3], dw_in[3], wq[3];
        arm_m3_tmul(rot[i], w, w_in);
        arm_m3_tmul(rot[i], dw, dw_in);
        for (int k = 0; k < 3; ++k) {
            wq[k] = l->axis[k] * qd[i];
        }
        arm_v3_cross(w_in, wq, t1);
        for (int k = 0; k < 3; ++k) {
            w[k] = w_in[k] + wq[k];
            dw[k] = dw_in[k] + l->axis[k] * qdd[i] + t1[k];
        }

        /* Newton-Euler at the centre of mass. */
        float ac[3], iw[3];
        arm_v3_cross(dw, l->com, t1);
        arm_v3_cross(w, l->com, t2);
        arm_v3_cross(w, t2, t2);
        for (int k = 0; k < 3; ++k) {
            ac[k] = acc[k] + t1[k] + t2[k];
            force[i][k] = l->mass * ac[k];
        }
        arm_m3_mul(l->inertia, w, iw);
        arm_v3_cross(w, iw, t1);
        arm_m3_mul(l->inertia, dw, t2);
        for (int k = 0; k < 3; ++k) {
            moment[i][k] = t2[k] + t1[k];
        }
    }

    /* Backward pass: f, n are the force and moment (about the body origin) the parent exerts. */
    float f[3] = {0.0f, 0.0f, 0.0f};
    float n[3] = {0.0f, 0.0f, 0.0f};
    for (int i = ARM_N_JOINTS - 1; i >= 0; --i) {
        const arm_link_t *l = &model->link[i];
        float f_child[3] = {0.0f, 0.0f, 0.0f};
        float n_child[3] = {0.0f, 0.0f, 0.0f};
        if (i + 1 < ARM_N_JOINTS) {
            /* Child's wrench in this frame, its moment carried over to this origin. */
            const float(*rc)[3] = rot[i + 1];
            float pxf[3];
            arm_m3_mul(rc, f, f_child);
            arm_m3_mul(rc, n, n_child);
            arm_v3_cross(model->link[i + 1].pos, f_child, pxf);
            for (int k = 0; k < 3; ++k) {
                n_child[k] += pxf[k];
            }
        }
        float cxf[3];
        arm_v3_cross(l->com, force[i], cxf);
        for (int k = 0; k < 3; ++k) {
            f[k] = force[i][k] + f_child[k];
            n[k] = moment[i][k] + cxf[k] + n_child[k];
        }
        tau[i] = arm_v3_dot(l->axis, n) + l->armature * qdd[i] + l->damping * qd[i];
    }
}
