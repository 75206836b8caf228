#include "step_reference.hpp"

#include "pm_design_float.h"

namespace ref {

namespace {

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
