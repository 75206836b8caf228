// Runs N control steps of one method so callgrind can count the instructions per step:
//   bench_step METHOD float|fixed|eigen N [DESIGN_FILE]
// "eigen" runs the dense double-precision reference (tests/c/reference) for the same method.
// DESIGN_FILE: the design read at run time (the Linux port's --design-file, gen.synth's
// pm_design.txt) instead of the built-in one: the run-time-sized path of the same step.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "step_reference.hpp"

extern "C" {
#include "arm_robot_model_data.h"
#include "design_file.h"
}

namespace {

void fill(int k, arm_ctl_input_t &in)
{
    const float t = 0.001f * float(k);
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        in.q[j] = 0.5f * std::sin(t + float(j));
        in.qd[j] = 0.5f * std::cos(t + float(j));
        in.q_d[j] = in.q[j] + 0.01f;
        in.qd_d[j] = in.qd[j];
        in.qdd_d[j] = 0.1f;
    }
    in.fresh_mask = (1u << ARM_N_JOINTS) - 1u;
}

}  // namespace

// Kept out of line so callgrind's --toggle-collect can name them.
extern "C" __attribute__((noinline)) void bench_firmware_step(arm_ctl_t *ctl, const arm_ctl_input_t *in,
                                                              arm_ctl_output_t *out)
{
    arm_ctl_step(ctl, in, out);
}

__attribute__((noinline)) ref::VecN bench_eigen_step(ref::Step &s, const arm_ctl_input_t &in)
{
    ref::VecN q, qd, q_d, qd_d, qdd_d;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        q[j] = in.q[j];
        qd[j] = in.qd[j];
        q_d[j] = in.q_d[j];
        qd_d[j] = in.qd_d[j];
        qdd_d[j] = in.qdd_d[j];
    }
    return s.step(q, qd, q_d, qd_d, qdd_d);
}

int main(int argc, char **argv)
{
    if (argc != 4 && argc != 5) {
        std::fprintf(stderr, "usage: %s METHOD float|fixed|eigen N [DESIGN_FILE]\n", argv[0]);
        return 2;
    }
    const arm_method_t method = arm_method_from_str(argv[1]);
    const int n = std::atoi(argv[3]);
    if (method == ARM_METHOD_COUNT || n <= 0) {
        std::fprintf(stderr, "bench_step: bad method '%s' or N '%s'\n", argv[1], argv[3]);
        return 2;
    }
    arm_ctl_config_t cfg;
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
    cfg.method = method;
    cfg.numeric = std::strcmp(argv[2], "fixed") == 0 ? ARM_NUMERIC_FIXED : ARM_NUMERIC_FLOAT;
    static design_file_t design;
    if (argc == 5) {
        char err[512];
        if (design_file_load(argv[4], &design, err, sizeof(err)) != 0) {
            std::fprintf(stderr, "bench_step: %s\n", err);
            return 2;
        }
        cfg.design = &design.d;
    }
    static arm_ctl_t ctl;
    if (arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) != ARM_CTL_OK) return 2;
    arm_ctl_input_t in{};
    arm_ctl_output_t out;
    double sink = 0.0;
    if (std::strcmp(argv[2], "eigen") == 0) {
        ref::Step s(ARM_ROBOT_MODEL, cfg);
        for (int k = 0; k < n; ++k) {
            fill(k, in);
            sink += bench_eigen_step(s, in)[0];
        }
    } else {
        for (int k = 0; k < n; ++k) {
            fill(k, in);
            bench_firmware_step(&ctl, &in, &out);
            std::memcpy(in.tau_measured, out.tau, sizeof(in.tau_measured));  // drives that do as told
            sink += out.tau[0];
        }
    }
    std::printf("%g\n", sink);
    return 0;
}
