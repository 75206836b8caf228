// The firmware's control step (float32, body-frame RNEA, per-joint blocks) against the plain
// double-precision Eigen model on 2,000 steps of random, smoothly varying inputs.
#include <cmath>
#include <cstdio>
#include <algorithm>
#include <random>

#include "step_reference.hpp"

extern "C" {
#include "arm_robot_model_data.h"
}

int main()
{
    int failed = 0, passed = 0;
    const arm_method_t methods[] = {ARM_METHOD_PD, ARM_METHOD_PM, ARM_METHOD_PM_PAPER, ARM_METHOD_GH2};
    for (arm_method_t method : methods) {
        arm_ctl_config_t cfg;
        arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
        cfg.method = method;
        static arm_ctl_t ctl;
        if (arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) != ARM_CTL_OK) return 2;
        ref::Step reference(ARM_ROBOT_MODEL, cfg);
        std::mt19937 rng(42);
        std::uniform_real_distribution<double> uni(-1.0, 1.0);
        double phase[ref::N], freq[ref::N];
        for (int j = 0; j < ref::N; ++j) {
            phase[j] = 3.0 * uni(rng);
            freq[j] = 2.0 + uni(rng);
        }
        double worst_tau = 0.0, worst_w = 0.0;
        float tau_applied[ref::N] = {};  // drives that do as told: they report last period's command
        for (int k = 0; k < 2000; ++k) {
            const double t = 1e-3 * k;
            arm_ctl_input_t in{};
            std::copy(tau_applied, tau_applied + ref::N, in.tau_measured);
            ref::VecN q, qd, q_d, qd_d, qdd_d;
            for (int j = 0; j < ref::N; ++j) {
                // float32 is what the firmware sees: give both models the same numbers.
                in.q[j] = float(std::sin(freq[j] * t + phase[j]));
                in.qd[j] = float(freq[j] * std::cos(freq[j] * t + phase[j]));
                in.q_d[j] = in.q[j] + float(0.02 * std::sin(7.0 * t + j));
                in.qd_d[j] = in.qd[j] + float(0.1 * std::cos(5.0 * t + j));
                in.qdd_d[j] = float(0.5 * uni(rng));
                q[j] = in.q[j];
                qd[j] = in.qd[j];
                q_d[j] = in.q_d[j];
                qd_d[j] = in.qd_d[j];
                qdd_d[j] = in.qdd_d[j];
            }
            in.fresh_mask = (1u << ref::N) - 1u;
            arm_ctl_output_t out;
            arm_ctl_step(&ctl, &in, &out);
            std::copy(out.tau, out.tau + ref::N, tau_applied);
            const ref::VecN tau = reference.step(q, qd, q_d, qd_d, qdd_d);
            double scale = 1.0;  // Nm: below that, compare absolutely
            for (int j = 0; j < ref::N; ++j) scale = std::max(scale, std::fabs(tau[j]));
            for (int j = 0; j < ref::N; ++j) {
                worst_tau = std::max(worst_tau, std::fabs(out.tau[j] - tau[j]) / scale);
                const double ws = std::max(1.0, std::fabs(reference.last_w_hat[j]));
                worst_w = std::max(worst_w, std::fabs(out.w_hat[j] - reference.last_w_hat[j]) / ws);
            }
        }
        const bool ok = worst_tau < 1e-4 && worst_w < 1e-3;
        (ok ? passed : failed)++;
        std::printf("%-9s worst relative torque error %.3g, w_hat %.3g over 2000 steps: %s\n",
                    arm_method_str(method), worst_tau, worst_w, ok ? "ok" : "FAILED");
    }
    std::printf("%d passed, %d failed\n", passed, failed);
    return failed == 0 ? 0 : 1;
}
