/* The simulated arm: MuJoCo integrates the true dynamics, which differ from the nominal model the
 * firmware believes in by a seeded, configurable uncertainty:
 *
 * - paper-style (Kim & Kim 2024, Example 1): (M + M~(t)) q_ddot + V + V~(t) = tau, with
 *   M~ = (D M + M D) / 2, D = diag(d_j(t)), V~_j = d'_j(t) V_j, every d(t) a random
 *   piecewise-linear signal in [-r, r] with a new value every knot_s seconds; V is MuJoCo's bias
 *   force (Coriolis, centrifugal, gravity);
 * - parametric: link masses, inertias and centres of mass off from the nominal model (uniform in
 *   +-error, per link, seeded);
 * - joint friction the nominal model lacks: viscous b and Coulomb c added to the true model's
 *   joint damping and frictionloss (MuJoCo integrates them stably, and frictionloss sticks);
 * - flexible joints (a plant model, gen/drivetrain.py): each a rotor behind its gear, a torsional
 *   spring and damper (a fixed tendon rotor - link), then the link; the motors drive the rotors,
 *   the motor encoders read them; the gears' stiffness can be scaled;
 * - a payload at the flange (the model's site "payload"), fixed or drawn by the seed.
 *
 * Each step returns w, the total uncertainty of e_ddot = u + w as the controller sees it: the
 * acceleration the firmware's nominal model predicts for the commanded torque minus the true one.
 * The nominal model is the arm's file (--model) with constraints (joint limits, frictionloss,
 * contacts) and springs off: rigid bodies, armature and damping, exactly what the firmware's RNEA
 * has. The true arm is the same file, or the plant (--plant): the same links, joints first. */
#ifndef ARM_SIM_ARM_H
#define ARM_SIM_ARM_H

#include <stddef.h>
#include <stdint.h>

#include <mujoco/mujoco.h>

#include "sim_rng.h"

#define SIM_MAX_JOINTS 16

typedef struct {
    uint64_t seed;
    double paper_ratio;  /* r; 0 disables the paper-style uncertainty */
    double paper_knot_s;
    double mass_error;   /* relative, per link */
    double inertia_error;
    double com_error_m;  /* metres, per link and axis */
    double viscous[SIM_MAX_JOINTS]; /* Nm s/rad per joint */
    double coulomb[SIM_MAX_JOINTS]; /* Nm per joint */
    double gear_stiffness_scale;    /* the plant's gear stiffness times this */
    double payload_kg[2];           /* at the flange: [m, m] fixed, [lo, hi] drawn; {0, 0}: none */
} sim_uncertainty_t;

typedef struct {
    mjModel *model;   /* the true arm (the plant, perturbed) */
    mjData *data;
    mjModel *nominal; /* what the firmware's model was generated from */
    mjData *nominal_data;
    int n;
    double period;
    int64_t step_count;
    sim_uncertainty_t unc;
    int parametric;
    /* the nominal model is not the true arm's links: parametric error or a payload (w needs a
     * forward pass of the nominal model) */
    int nominal_differs;
    /* per joint, the plant's dof and qpos of its motor: the rotor of a flexible joint, else the
     * link's own (joint j's link is dof j and qpos j in both models) */
    int motor_dof[SIM_MAX_JOINTS];
    int motor_qpos[SIM_MAX_JOINTS];
    int flexible;     /* joints with a rotor of their own */
    double payload_kg;
    /* w from the true arm's own step (its unconstrained acceleration and mass matrix) instead of
     * a forward pass of the nominal model: the same quantity, when the two models differ only in
     * what sim_arm_open checks (sim_arm.c: w_from_true_arm); about a fifth of a SIL period */
    int w_from_true_arm;
    /* the same on the arm with flexible joints: from the plant's links (sim_arm.c: w_from_flexible_plant) */
    int w_from_plant;
    sim_rng_t rng;
    double knots[2][2 * SIM_MAX_JOINTS]; /* the random signal d (first n) and d' (last n) */
    int64_t knot_index;
    double mass[SIM_MAX_JOINTS * SIM_MAX_JOINTS]; /* the links' mass matrix (the plant's link block) */
    double mass_full[4 * SIM_MAX_JOINTS * SIM_MAX_JOINTS]; /* scratch: the plant's whole one */
    double torque_limit[SIM_MAX_JOINTS];
    /* The holding brakes (sim_arm_set_brake): each motor dof's own dry friction and its constraint's
     * softness, restored when its brake opens; the joint's inertia a drive's velocity loop is tuned
     * for (its motor dof and, on a flexible joint, the link behind it, at the start pose). */
    double own_frictionloss[SIM_MAX_JOINTS];
    double own_solref[SIM_MAX_JOINTS][mjNREF];
    double own_solimp[SIM_MAX_JOINTS][mjNIMP];
    double brake_nm[SIM_MAX_JOINTS];
    double drive_inertia[SIM_MAX_JOINTS];
    int substeps;             /* MuJoCo steps per period (the model's timestep x substeps = period) */
    unsigned long long model_hash; /* FNV-1a 64 of the model file: announced at boot (SIM_IDENTITY) */
} sim_arm_t;

void sim_uncertainty_default(sim_uncertainty_t *u);
/* Loads the nominal model (path) and the true arm (plant, or path again when plant is NULL or
 * ""), draws the uncertainty, resets to the keyframe with every gear wound up against gravity.
 * Returns 0, or -1 with a message naming the file, option or element in err. */
int sim_arm_open(sim_arm_t *a, const char *path, const char *plant, const char *keyframe, int substeps,
                 const sim_uncertainty_t *u, char *err, size_t errcap);
/* Joint j's motor angle and speed, in joint units: its rotor's, or the link's on a rigid joint. */
double sim_arm_motor_q(const sim_arm_t *a, int j);
double sim_arm_motor_qd(const sim_arm_t *a, int j);
/* FNV-1a 64 of a file's bytes (gen/arm.py's fnv1a64), or 0 if it cannot be read. */
unsigned long long sim_file_hash(const char *path);
/* Start at pose q (rad per joint, inside each joint's range) at rest instead of the keyframe: -1 with
 * the joint and value named in err otherwise. */
int sim_arm_set_pose(sim_arm_t *a, const double *q, char *err, size_t errcap);
/* Joint j's holding brake: holding_nm (N m at the joint; 0: open) of dry friction on its motor dof,
 * on top of the joint's own, as a stiff constraint: it holds a load below it (creep under 0.01 deg
 * in 2 s at the bundled arm's most loaded pose) and slips above it. */
void sim_arm_set_brake(sim_arm_t *a, int j, double holding_nm);
/* One period under tau (the time average the joints feel); tau_commanded (may be NULL: tau) is
 * what the controller commanded, when the bus delays a new command into the period. w: n values.
 * Returns 0, or the 1-based DOF whose acceleration MuJoCo found NaN, infinite or huge: the
 * simulation diverged, and MuJoCo has reset the arm to its initial state. */
int sim_arm_step(sim_arm_t *a, const double *tau, const double *tau_commanded, double *w);
/* The run's reason when sim_arm_step reported joint `dof` (1-based) diverged, after `periods`. */
void sim_arm_diverged_text(const sim_arm_t *a, int dof, unsigned long long periods, char *out, unsigned long cap);
void sim_arm_close(sim_arm_t *a);

#endif
