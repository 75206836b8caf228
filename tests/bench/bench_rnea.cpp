// The inverse dynamics alone, ours and Pinocchio's, on the same arm and inputs, so callgrind can
// count the instructions per call:
//   bench_rnea ours|kernel|pinocchio-double|pinocchio-float N
// (ours: the general arm_rnea; kernel: the arm's generated arm_rnea_kernel, what the controller runs)
//   bench_rnea check        (Pinocchio's torques against ours on 200 states; prints the worst;
//                            tests/python/test_bench_rnea.py makes the same comparison without compiling Pinocchio)
// Pinocchio's model is built from the same generated header the firmware uses: the same link
// frames, axes, masses, centres of mass, inertias, armature (model.armature, which Pinocchio's
// rnea adds as armature * a) and joint damping (model.damping, which its rnea leaves out: our
// RNEA adds damping * qd, so every Pinocchio call here adds it too, inside the counted function).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

extern "C" {
#include "arm/rnea.h"
#include "arm_rnea_kernel.h"
#include "arm_robot_model_data.h"
}
#include "rnea_states.h"

namespace {

template <typename S>
pinocchio::ModelTpl<S> build_model()
{
    using Model = pinocchio::ModelTpl<S>;
    using Vec3 = Eigen::Matrix<S, 3, 1>;
    using Mat3 = Eigen::Matrix<S, 3, 3>;
    Model m;
    m.gravity.linear(Vec3(S(ARM_ROBOT_MODEL.gravity[0]), S(ARM_ROBOT_MODEL.gravity[1]), S(ARM_ROBOT_MODEL.gravity[2])));
    typename Model::JointIndex parent = 0;
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const arm_link_t &l = ARM_ROBOT_MODEL.link[i];
        Mat3 r, inertia;
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) {
                r(a, b) = S(l.rot[a][b]);
                inertia(a, b) = S(l.inertia[a][b]);
            }
        const pinocchio::SE3Tpl<S> placement(r, Vec3(S(l.pos[0]), S(l.pos[1]), S(l.pos[2])));
        const std::string name = "joint" + std::to_string(i + 1);
        typename Model::JointIndex id;
        if (l.axis[0] == 0.0f && l.axis[1] == 0.0f && l.axis[2] == 1.0f) {
            id = m.addJoint(parent, pinocchio::JointModelRevoluteTpl<S, 0, 2>(), placement, name);
        } else {
            id = m.addJoint(parent, pinocchio::JointModelRevoluteUnalignedTpl<S>(S(l.axis[0]), S(l.axis[1]), S(l.axis[2])),
                            placement, name);
        }
        m.appendBodyToJoint(id, pinocchio::InertiaTpl<S>(S(l.mass), Vec3(S(l.com[0]), S(l.com[1]), S(l.com[2])), inertia),
                            pinocchio::SE3Tpl<S>::Identity());
        m.armature[i] = S(l.armature);
        m.damping[i] = S(l.damping);
        parent = id;
    }
    return m;
}

}  // namespace

// Kept out of line so callgrind's --toggle-collect can name them.
extern "C" __attribute__((noinline)) void bench_rnea_ours(const float *q, const float *qd, const float *qdd, float *tau)
{
    arm_rnea(&ARM_ROBOT_MODEL, q, qd, qdd, tau);
}

extern "C" __attribute__((noinline)) void bench_rnea_kernel(const float *q, const float *qd, const float *qdd, float *tau)
{
    arm_rnea_kernel(q, qd, qdd, tau);
}

template <typename S>
__attribute__((noinline)) void bench_rnea_pinocchio(const pinocchio::ModelTpl<S> &m, pinocchio::DataTpl<S> &d,
                                                    const Eigen::Matrix<S, Eigen::Dynamic, 1> &q,
                                                    const Eigen::Matrix<S, Eigen::Dynamic, 1> &v,
                                                    const Eigen::Matrix<S, Eigen::Dynamic, 1> &a)
{
    pinocchio::rnea(m, d, q, v, a);
    d.tau.array() += m.damping.array() * v.array(); // the joint's viscous damping: see the top
}

template <typename S>
double run_pinocchio(int n)
{
    const auto m = build_model<S>();
    pinocchio::DataTpl<S> d(m);
    Eigen::Matrix<S, Eigen::Dynamic, 1> q(ARM_N_JOINTS), v(ARM_N_JOINTS), a(ARM_N_JOINTS);
    double sink = 0.0;
    for (int k = 0; k < n; ++k) {
        float fq[ARM_N_JOINTS], fv[ARM_N_JOINTS], fa[ARM_N_JOINTS];
        arm_rnea_state(k, fq, fv, fa);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            q[j] = S(fq[j]);
            v[j] = S(fv[j]);
            a[j] = S(fa[j]);
        }
        bench_rnea_pinocchio<S>(m, d, q, v, a);
        sink += double(d.tau[0]);
    }
    return sink;
}

int main(int argc, char **argv)
{
    if (argc == 2 && std::strcmp(argv[1], "check") == 0) {
        const auto m = build_model<double>();
        pinocchio::Data d(m);
        double worst = 0.0;
        for (int k = 0; k < ARM_RNEA_CHECK_STATES; ++k) {
            float q[ARM_N_JOINTS], qd[ARM_N_JOINTS], qdd[ARM_N_JOINTS], tau[ARM_N_JOINTS];
            arm_rnea_state(ARM_RNEA_CHECK_STRIDE * k, q, qd, qdd);
            Eigen::VectorXd vq(ARM_N_JOINTS), vv(ARM_N_JOINTS), va(ARM_N_JOINTS);
            for (int j = 0; j < ARM_N_JOINTS; ++j) {
                vq[j] = q[j];
                vv[j] = qd[j];
                va[j] = qdd[j];
            }
            bench_rnea_pinocchio<double>(m, d, vq, vv, va);
            float tau_k[ARM_N_JOINTS];
            arm_rnea(&ARM_ROBOT_MODEL, q, qd, qdd, tau);
            arm_rnea_kernel(q, qd, qdd, tau_k);
            // (bench_rnea_pinocchio has added the joint damping Pinocchio's rnea leaves out)
            double want[ARM_N_JOINTS], scale = 1.0;
            for (int j = 0; j < ARM_N_JOINTS; ++j) {
                want[j] = d.tau[j];
                scale = std::max(scale, std::fabs(want[j]));
            }
            for (int j = 0; j < ARM_N_JOINTS; ++j) {
                worst = std::max(worst, std::fabs(double(tau[j]) - want[j]) / scale);
                worst = std::max(worst, std::fabs(double(tau_k[j]) - want[j]) / scale);
            }
        }
        std::printf("pinocchio vs arm_rnea and arm_rnea_kernel over 200 states: worst relative difference %.3g\n", worst);
        return worst < 1e-5 ? 0 : 1;
    }
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s ours|kernel|pinocchio-double|pinocchio-float N | check\n", argv[0]);
        return 2;
    }
    const int n = std::atoi(argv[2]);
    double sink = 0.0;
    if (std::strcmp(argv[1], "ours") == 0 || std::strcmp(argv[1], "kernel") == 0) {
        const bool kernel = std::strcmp(argv[1], "kernel") == 0;
        for (int k = 0; k < n; ++k) {
            float q[ARM_N_JOINTS], qd[ARM_N_JOINTS], qdd[ARM_N_JOINTS], tau[ARM_N_JOINTS];
            arm_rnea_state(k, q, qd, qdd);
            if (kernel) {
                bench_rnea_kernel(q, qd, qdd, tau);
            } else {
                bench_rnea_ours(q, qd, qdd, tau);
            }
            sink += double(tau[0]);
        }
    } else if (std::strcmp(argv[1], "pinocchio-double") == 0) {
        sink = run_pinocchio<double>(n);
    } else if (std::strcmp(argv[1], "pinocchio-float") == 0) {
        sink = run_pinocchio<float>(n);
    } else {
        std::fprintf(stderr, "bench_rnea: unknown '%s'\n", argv[1]);
        return 2;
    }
    std::printf("%g\n", sink);
    return 0;
}
