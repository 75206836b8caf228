// The reference's rigid-body dynamics, in a file of its own: the reference's Eigen code in two halves
// that compile on two cores (as one file it compiled alone, 20 s, at the end of the sanitizer build).
#include "step_reference.hpp"

namespace ref {

namespace {

Eigen::Matrix3d mat3(const float m[3][3])
{
    Eigen::Matrix3d r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = m[i][j];
    return r;
}

Eigen::Vector3d vec3(const float v[3])
{
    return Eigen::Vector3d(v[0], v[1], v[2]);
}

}  // namespace

VecN inverse_dynamics(const arm_robot_model_t &model, const VecN &q, const VecN &qd, const VecN &qdd)
{
    Eigen::Matrix3d R[N];
    Eigen::Vector3d p[N], z[N], c[N], w[N], dw[N], ao[N], F[N], Nm[N];
    Eigen::Matrix3d R_prev = Eigen::Matrix3d::Identity();
    Eigen::Vector3d p_prev = Eigen::Vector3d::Zero(), w_prev = Eigen::Vector3d::Zero(),
                    dw_prev = Eigen::Vector3d::Zero(), a_prev = -vec3(model.gravity);
    for (int i = 0; i < N; ++i) {
        const arm_link_t &l = model.link[i];
        const Eigen::Vector3d axis = vec3(l.axis);
        p[i] = p_prev + R_prev * vec3(l.pos);
        R[i] = R_prev * mat3(l.rot) * Eigen::AngleAxisd(q[i], axis).toRotationMatrix();
        z[i] = R[i] * axis;
        c[i] = p[i] + R[i] * vec3(l.com);
        const Eigen::Vector3d d = p[i] - p_prev;
        ao[i] = a_prev + dw_prev.cross(d) + w_prev.cross(w_prev.cross(d));
        w[i] = w_prev + z[i] * qd[i];
        dw[i] = dw_prev + z[i] * qdd[i] + w_prev.cross(z[i] * qd[i]);
        const Eigen::Vector3d r = c[i] - p[i];
        const Eigen::Vector3d ac = ao[i] + dw[i].cross(r) + w[i].cross(w[i].cross(r));
        const Eigen::Matrix3d Iw = R[i] * mat3(l.inertia) * R[i].transpose();
        F[i] = l.mass * ac;
        Nm[i] = Iw * dw[i] + w[i].cross(Iw * w[i]);
        R_prev = R[i];
        p_prev = p[i];
        w_prev = w[i];
        dw_prev = dw[i];
        a_prev = ao[i];
    }
    VecN tau;
    Eigen::Vector3d f = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
    for (int i = N - 1; i >= 0; --i) {
        const Eigen::Vector3d f_child = f;
        const Eigen::Vector3d n_child = n;
        f = F[i] + f_child;
        n = Nm[i] + n_child + (c[i] - p[i]).cross(F[i]);
        if (i + 1 < N) n += (p[i + 1] - p[i]).cross(f_child);
        tau[i] = z[i].dot(n) + model.link[i].armature * qdd[i] + model.link[i].damping * qd[i];
    }
    return tau;
}

MatN mass_matrix(const arm_robot_model_t &model, const VecN &q)
{
    arm_robot_model_t no_gravity = model;
    no_gravity.gravity[0] = no_gravity.gravity[1] = no_gravity.gravity[2] = 0.0f;
    MatN M;
    for (int j = 0; j < N; ++j)
        M.col(j) = inverse_dynamics(no_gravity, q, VecN::Zero(), VecN::Unit(j));
    return M;
}

}  // namespace ref
