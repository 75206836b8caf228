#include "step_reference.hpp"

#include "pm_design_float.h"

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

template <int R, int C>
Eigen::MatrixXd kron_eye(const float (&m)[R][C])
{
    Eigen::MatrixXd one(R, C);
    for (int i = 0; i < R; ++i)
        for (int j = 0; j < C; ++j) one(i, j) = m[i][j];
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(R * N, C * N);
    for (int k = 0; k < N; ++k) out.block(k * R, k * C, R, C) = one;
    return out;
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

Step::Step(const arm_robot_model_t &model, const arm_ctl_config_t &cfg) : model_(model), cfg_(cfg)
{
    Ak_ = kron_eye(ARM_EST_A);
    Bk_ = kron_eye(ARM_EST_B);
    Ck_ = kron_eye(ARM_EST_C);
    Dk_ = kron_eye(ARM_EST_D);
    Ac_ = kron_eye(ARM_CTL_A);
    Bc_ = kron_eye(ARM_CTL_B);
    Cc_ = kron_eye(ARM_CTL_C);
    Dc_ = kron_eye(ARM_CTL_D);
    Am_ = kron_eye(ARM_IM_A);
    Bm_ = kron_eye(ARM_IM_B);
    xk_ = Eigen::VectorXd::Zero(Ak_.rows());
    xc_ = Eigen::VectorXd::Zero(Ac_.rows());
    xm_ = Eigen::VectorXd::Zero(2 * N);
    tau_prev_.setZero();
    last_w_hat.setZero();
    last_u_o.setZero();
}

VecN Step::step(const VecN &q, const VecN &qd, const VecN &q_d, const VecN &qd_d, const VecN &qdd_d)
{
    const VecN e = q_d - q, e_dot = qd_d - qd;
    Eigen::VectorXd y(2 * N);  // per joint [e_j, e_dot_j], joints stacked
    for (int j = 0; j < N; ++j) {
        y[2 * j] = e[j];
        y[2 * j + 1] = e_dot[j];
    }
    const bool pm = cfg_.method == ARM_METHOD_PM || cfg_.method == ARM_METHOD_PM_PAPER ||
                    cfg_.method == ARM_METHOD_GH2;
    VecN u_o, w_hat = VecN::Zero();
    Eigen::VectorXd v = y;
    if (first_) xm_ = y;  // the internal model starts at the first measurement
    first_ = false;
    if (pm) {
        u_o = Cc_ * xc_ + Dc_ * y;
        if (cfg_.method == ARM_METHOD_PM) v = y - xm_;
        if (cfg_.method != ARM_METHOD_GH2) w_hat = Ck_ * xk_ + Dk_ * v;
    } else {  // pd
        u_o = -cfg_.kp * e - cfg_.kd * e_dot;
    }
    const VecN acc = qdd_d - (u_o - w_hat);
    const VecN h = inverse_dynamics(model_, q, qd, VecN::Zero());
    VecN tau = mass_matrix(model_, q) * acc + h;

    bool limited[N];
    for (int j = 0; j < N; ++j) {
        const double want = tau[j];
        double t = std::clamp(want, tau_prev_[j] - cfg_.torque_rate_limit[j], tau_prev_[j] + cfg_.torque_rate_limit[j]);
        t = std::clamp(t, -double(cfg_.torque_limit[j]), double(cfg_.torque_limit[j]));
        limited[j] = t != want;
        tau[j] = t;
    }
    if (pm) {
        xc_ = Ac_ * xc_ + Bc_ * y;
        if (cfg_.method != ARM_METHOD_GH2) {
            const Eigen::VectorXd xk_next = Ak_ * xk_ + Bk_ * v;
            const Eigen::VectorXd xm_next = Am_ * xm_ + Bm_ * u_o;
            const int nk = int(Ak_.rows()) / N;
            for (int j = 0; j < N; ++j) {
                if (!limited[j]) {
                    xk_.segment(j * nk, nk) = xk_next.segment(j * nk, nk);
                    xm_.segment(2 * j, 2) = xm_next.segment(2 * j, 2);
                } else {
                    xm_.segment(2 * j, 2) = y.segment(2 * j, 2);
                }
            }
            if (cfg_.method != ARM_METHOD_PM) xm_.setZero();
        }
    }
    tau_prev_ = tau;
    last_w_hat = w_hat;
    last_u_o = u_o;
    return tau;
}

}  // namespace ref
