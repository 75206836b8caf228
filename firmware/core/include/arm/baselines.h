/* The paper's comparison methods, on the same inverse dynamics: every method produces u_o and
 * w_hat, and the torque is tau = M_hat(q) (q_ddot_d - (u_o - w_hat)) + V_hat + G. */
#ifndef ARM_BASELINES_H
#define ARM_BASELINES_H

#include <stdint.h>

#include "arm/robot_model.h"

/* Time-delay estimation on the IDC: the disturbance of the last period is what the commanded
 * nominal acceleration did not produce, w(k-1) = a(k-1) - q_ddot(k-1), with q_ddot(k-1) =
 * (qd(k) - qd(k-1)) / T (backward difference of the measured velocity), smoothed by a
 * first-order low-pass (exact discretisation, alpha = exp(-2 pi fc T)) because differencing
 * amplifies velocity noise by 1/T. */
typedef struct {
    float alpha;
    float period_s;
    int primed;
    float a_prev[ARM_N_JOINTS];
    float qd_prev[ARM_N_JOINTS];
    float w_hat[ARM_N_JOINTS];
} arm_tde_t;

void arm_tde_init(arm_tde_t *t, float period_s, float cutoff_hz);
/* w_hat for this period from the measured qd (needs the previous period's a). */
void arm_tde_output(arm_tde_t *t, const float qd[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS]);
/* Remember this period's commanded acceleration; joints in hold_mask keep their estimate. */
void arm_tde_update(arm_tde_t *t, const float qd[ARM_N_JOINTS], const float a[ARM_N_JOINTS],
                    uint32_t hold_mask);

/* USDE (Na et al., IEEE TIE 2020) on the IDC: filters k x_f' + x_f = qd and k a_f' + a_f = a give
 * w_hat = a_f - (qd - x_f) / k, i.e. w filtered by 1/(k s + 1); discretised exactly,
 * alpha = exp(-T / k). Paired with sliding-mode control s = e_dot + lambda e,
 * u_o = -lambda e_dot - eta sat(s / phi) - ks s (boundary layer phi against chattering). */
typedef struct {
    float alpha;
    float k;
    float lambda, eta, phi, ks;
    int primed;
    float x_f[ARM_N_JOINTS];
    float a_f[ARM_N_JOINTS];
    float w_hat[ARM_N_JOINTS]; /* this period's estimate */
} arm_usde_smc_t;

void arm_usde_smc_init(arm_usde_smc_t *u, float period_s, float k, float lambda, float eta,
                       float phi, float ks);
void arm_usde_smc_output(arm_usde_smc_t *u, const float e[ARM_N_JOINTS],
                         const float e_dot[ARM_N_JOINTS], const float qd[ARM_N_JOINTS],
                         float u_o[ARM_N_JOINTS], float w_hat[ARM_N_JOINTS]);
void arm_usde_smc_update(arm_usde_smc_t *u, const float qd[ARM_N_JOINTS],
                         const float a[ARM_N_JOINTS], uint32_t hold_mask);

#endif
