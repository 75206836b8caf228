// An independent golden model of the whole control step, in double precision with Eigen,
// written plainly: dense matrices, the joint-space mass matrix formed explicitly, and a
// world-frame Newton-Euler (the firmware uses body frames and never forms M).
#pragma once

#include <Eigen/Dense>

extern "C" {
#include "arm/controller.h"
}

namespace ref {

constexpr int N = ARM_N_JOINTS;
using VecN = Eigen::Matrix<double, N, 1>;
using MatN = Eigen::Matrix<double, N, N>;

// tau = M(q) qdd + h(q, qd), world-frame recursive Newton-Euler.
VecN inverse_dynamics(const arm_robot_model_t &model, const VecN &q, const VecN &qd, const VecN &qdd);
MatN mass_matrix(const arm_robot_model_t &model, const VecN &q);

class Step {
  public:
    Step(const arm_robot_model_t &model, const arm_ctl_config_t &cfg);
    // Same contract as arm_ctl_step for a running controller with fresh inputs.
    VecN step(const VecN &q, const VecN &qd, const VecN &q_d, const VecN &qd_d, const VecN &qdd_d);
    VecN last_w_hat, last_u_o;

  private:
    const arm_robot_model_t &model_;
    arm_ctl_config_t cfg_;
    // Dense, all joints at once: kron(I_n, one joint's matrices).
    Eigen::MatrixXd Ak_, Bk_, Ck_, Dk_, Ac_, Bc_, Cc_, Dc_, Am_, Bm_;
    Eigen::VectorXd xk_, xc_, xm_;
    VecN tau_prev_;
    bool first_ = true;
};

}  // namespace ref
