#include "sim_arm.h"

#include "arm_params.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

void sim_uncertainty_default(sim_uncertainty_t *u)
{
    memset(u, 0, sizeof(*u));
    u->seed = ARM_P_SIMULATOR_SEED_DEFAULT;
    u->paper_knot_s = ARM_P_SIMULATOR_PAPER_KNOT_S_DEFAULT;
    u->gear_stiffness_scale = ARM_P_SIMULATOR_GEAR_STIFFNESS_SCALE_DEFAULT;
}

static void draw_knot(sim_arm_t *a, double *dst)
{
    const double r = a->unc.paper_ratio;
    for (int i = 0; i < 2 * a->n; ++i) {
        dst[i] = sim_rng_uniform(&a->rng, -r, r);
    }
}

/* Parametric error: the simulated arm's links differ from the nominal ones. */
static void perturb(sim_arm_t *a)
{
    mjModel *m = a->model;
    const sim_uncertainty_t *u = &a->unc;
    for (int b = 1; b < a->nominal->nbody; ++b) { /* the arm's links (a plant's rotors come after them) */
        if (u->mass_error != 0.0) {
            m->body_mass[b] *= 1.0 + sim_rng_uniform(&a->rng, -u->mass_error, u->mass_error);
        }
        if (u->inertia_error != 0.0) {
            const double s = 1.0 + sim_rng_uniform(&a->rng, -u->inertia_error, u->inertia_error);
            for (int k = 0; k < 3; ++k) {
                m->body_inertia[3 * b + k] *= s;
            }
        }
        if (u->com_error_m != 0.0) {
            for (int k = 0; k < 3; ++k) {
                m->body_ipos[3 * b + k] += sim_rng_uniform(&a->rng, -u->com_error_m, u->com_error_m);
            }
        }
    }
}

unsigned long long sim_file_hash(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL) return 0;
    unsigned long long h = 0xCBF29CE484222325ull;
    int c;
    while ((c = fgetc(f)) != EOF) {
        h = (h ^ (unsigned char)c) * 0x100000001B3ull;
    }
    fclose(f);
    return h;
}

/* Whether the nominal model's acceleration follows from the true arm's step without a forward pass
 * of its own: the same links (no parametric error), an integrator that steps from the forward
 * pass once (Euler, implicit, implicitfast: its M factor and accelerations survive the step; RK4
 * runs four passes, and mj_step2 would not even use it), no springs (the nominal model has them off), and joint motors whose force is
 * gain x control (so the commanded torque's force is known without MuJoCo's actuation stage). */
static int w_from_true_arm(const sim_arm_t *a)
{
    const mjModel *m = a->model;
    if (a->nominal_differs || a->flexible || m->opt.integrator == mjINT_RK4 ||
        (m->opt.disableflags & mjDSBL_ACTUATION) != 0) {
        return 0;
    }
    for (int j = 0; j < m->njnt; ++j) {
        if (m->jnt_stiffness[j] != 0.0 || m->jnt_actgravcomp[j]) return 0;
    }
    for (int t = 0; t < m->ntendon; ++t) {
        if (m->tendon_stiffness[t] != 0.0) return 0;
    }
    for (int i = 0; i < m->nu; ++i) {
        const int jnt = m->actuator_trnid[2 * i];
        if (m->actuator_dyntype[i] != mjDYN_NONE || m->actuator_gaintype[i] != mjGAIN_FIXED ||
            m->actuator_biastype[i] != mjBIAS_NONE || m->actuator_trntype[i] != mjTRN_JOINT ||
            (m->jnt_type[jnt] != mjJNT_HINGE && m->jnt_type[jnt] != mjJNT_SLIDE)) {
            return 0;
        }
    }
    return 1;
}

/* Whether, on the arm with flexible joints, the nominal model's acceleration follows from the
 * plant's own step: the same links (no parametric error, no payload), so the plant's link block
 * of M and its links' bias forces are the nominal model's, less the armature the nominal model
 * gives the links (the plant's rotors carry it); and a nominal model of plain joint motors, no
 * tendons, no gravity compensation and no fluid forces, so its forward pass adds nothing else. */
static int w_from_flexible_plant(const sim_arm_t *a)
{
    const mjModel *nm = a->nominal;
    if (!a->flexible || a->nominal_differs || nm->ntendon != 0 || nm->opt.density != 0.0 || nm->opt.viscosity != 0.0 ||
        (nm->opt.disableflags & mjDSBL_ACTUATION) != 0) {
        return 0;
    }
    for (int j = 0; j < nm->njnt; ++j) {
        if (nm->jnt_actgravcomp[j]) return 0;
    }
    for (int i = 0; i < nm->nu; ++i) {
        if (nm->actuator_dyntype[i] != mjDYN_NONE || nm->actuator_gaintype[i] != mjGAIN_FIXED ||
            nm->actuator_biastype[i] != mjBIAS_NONE || nm->actuator_trntype[i] != mjTRN_JOINT) {
            return 0;
        }
    }
    return 1;
}

/* The plant's joints against the nominal model's: joint j's link is dof j and qpos j in both (the
 * plant only adds rotors after the links), a hinge; its motor drives the link or a rotor of its own. */
static int map_plant(sim_arm_t *a, const char *plant, char *err, size_t errcap)
{
    const mjModel *m = a->model, *nm = a->nominal;
    int rotors = 0;
    for (int j = 0; j < a->n; ++j) {
        const char *name = mj_id2name(nm, mjOBJ_JOINT, nm->actuator_trnid[2 * j]);
        const int link = name != NULL ? mj_name2id(m, mjOBJ_JOINT, name) : -1;
        if (link < 0 || m->jnt_dofadr[link] != j || m->jnt_qposadr[link] != j || m->jnt_type[link] != mjJNT_HINGE) {
            snprintf(err, errcap, "--plant: '%s' does not carry the arm's joint %d ('%s') as its hinge dof %d: make "
                     "it from the same arm.xml (gen/drivetrain.py)", plant, j + 1, name != NULL ? name : "?", j);
            return -1;
        }
        const int motor = m->actuator_trnid[2 * j];
        if (m->actuator_trntype[j] != mjTRN_JOINT || m->jnt_type[motor] != mjJNT_HINGE) {
            snprintf(err, errcap, "--plant: '%s': actuator %d is not a motor on a hinge", plant, j + 1);
            return -1;
        }
        a->motor_dof[j] = m->jnt_dofadr[motor];
        a->motor_qpos[j] = m->jnt_qposadr[motor];
        rotors += motor != link;
    }
    if (m->nv != a->n + rotors || m->nq != m->nv) {
        snprintf(err, errcap, "--plant: '%s' has %ld degrees of freedom: the arm's %d and one per rotor (%d)", plant,
                 (long)m->nv, a->n, rotors);
        return -1;
    }
    a->flexible = rotors;
    return 0;
}

/* The payload, a solid sphere of PAYLOAD_RADIUS_M at the site "payload", merged into its body:
 * mass, centre of mass and inertia about it (principal axes anew). */
#define PAYLOAD_RADIUS_M 0.05
static int add_payload(sim_arm_t *a, double kg, char *err, size_t errcap)
{
    mjModel *m = a->model;
    const int site = mj_name2id(m, mjOBJ_SITE, "payload");
    if (site < 0) {
        snprintf(err, errcap, "--payload-kg: the model has no site 'payload' to hang it on (arm.xml has it when "
                 "gen/arm.py prepared the arm)");
        return -1;
    }
    const int b = m->site_bodyid[site];
    const double m0 = m->body_mass[b], m1 = m0 + kg;
    double c1[3], rot[9], i0[9] = {0}, itot[9] = {0};
    for (int k = 0; k < 3; ++k) c1[k] = (m0 * m->body_ipos[3 * b + k] + kg * m->site_pos[3 * site + k]) / m1;
    /* the body's inertia in its frame: R diag(I) R^T */
    mju_quat2Mat(rot, m->body_iquat + 4 * b);
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
            for (int k = 0; k < 3; ++k) i0[3 * r + c] += rot[3 * r + k] * m->body_inertia[3 * b + k] * rot[3 * c + k];
        }
    }
    const double sphere = 0.4 * kg * PAYLOAD_RADIUS_M * PAYLOAD_RADIUS_M;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) itot[3 * r + c] = i0[3 * r + c] + (r == c ? sphere : 0.0);
    }
    /* both masses moved to the common centre of mass (parallel axes) */
    const double *at[2] = {m->body_ipos + 3 * b, m->site_pos + 3 * site};
    const double mass[2] = {m0, kg};
    for (int p = 0; p < 2; ++p) {
        double dv[3];
        for (int k = 0; k < 3; ++k) dv[k] = at[p][k] - c1[k];
        const double d2 = dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2];
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) itot[3 * r + c] += mass[p] * ((r == c ? d2 : 0.0) - dv[r] * dv[c]);
        }
    }
    double eigval[3], eigvec[9];
    mju_eig3(eigval, eigvec, m->body_iquat + 4 * b, itot);
    for (int k = 0; k < 3; ++k) {
        m->body_inertia[3 * b + k] = eigval[k];
        m->body_ipos[3 * b + k] = c1[k];
    }
    m->body_mass[b] = m1;
    return 0;
}

/* The rigid links' static equilibrium at the keyframe: each rotor ahead of its link by the gear's
 * wind-up under gravity, so the arm starts at rest, as a real one holding its pose does. */
static void wind_up_gears(sim_arm_t *a)
{
    const mjModel *m = a->model;
    mjData *d = a->data;
    mj_forward(m, d);
    for (int t = 0; t < m->ntendon; ++t) {
        for (int w = m->tendon_adr[t]; w < m->tendon_adr[t] + m->tendon_num[t]; ++w) {
            if (m->wrap_type[w] != mjWRAP_JOINT || m->tendon_stiffness[t] <= 0.0) continue;
            for (int j = 0; j < a->n; ++j) {
                if (a->motor_dof[j] != j && m->wrap_objid[w] == m->dof_jntid[a->motor_dof[j]]) {
                    d->qpos[a->motor_qpos[j]] = d->qpos[j] + d->qfrc_bias[j] / m->tendon_stiffness[t];
                }
            }
        }
    }
    mj_forward(m, d);
}

static void remember_joints(sim_arm_t *a);

int sim_arm_open(sim_arm_t *a, const char *path, const char *plant, const char *keyframe, int substeps,
                 const sim_uncertainty_t *u, char *err, size_t errcap)
{
    memset(a, 0, sizeof(*a));
    const int has_plant = plant != NULL && plant[0] != '\0';
    const char *true_path = has_plant ? plant : path;
    char mjerr[500] = "";
    a->nominal = mj_loadXML(path, NULL, mjerr, sizeof(mjerr));
    if (a->nominal == NULL) {
        snprintf(err, errcap, "--model: cannot load '%s': %s", path, mjerr);
        sim_arm_close(a);
        return -1;
    }
    a->model = mj_loadXML(true_path, NULL, mjerr, sizeof(mjerr));
    if (a->model == NULL) {
        snprintf(err, errcap, "%s: cannot load '%s': %s", has_plant ? "--plant" : "--model", true_path, mjerr);
        sim_arm_close(a);
        return -1;
    }
    const long nu = (long)a->nominal->nu, nv = (long)a->nominal->nv;
    if (nu < 1 || nu > SIM_MAX_JOINTS || nv != nu || a->model->nu != a->nominal->nu) {
        snprintf(err, errcap, "--model: '%s' has %ld actuators and %ld degrees of freedom (its plant %ld actuators); "
                 "the simulator drives 1..%d joints, one actuator each", path, nu, nv, (long)a->model->nu, SIM_MAX_JOINTS);
        sim_arm_close(a);
        return -1;
    }
    a->n = (int)nu;
    if (map_plant(a, true_path, err, errcap) != 0) {
        sim_arm_close(a);
        return -1;
    }
    if (u->gear_stiffness_scale != 1.0 && a->flexible == 0) {
        snprintf(err, errcap, "--gear-stiffness-scale: the arm '%s' has no flexible joint (give --plant)", true_path);
        sim_arm_close(a);
        return -1;
    }
    a->unc = *u;
    a->substeps = substeps;
    a->period = a->model->opt.timestep * substeps;
    a->model_hash = sim_file_hash(path);
    /* The firmware's nominal model: no constraints (limits, frictionloss, contacts), no springs. */
    a->nominal->opt.disableflags |= mjDSBL_CONSTRAINT | mjDSBL_SPRING;
    a->parametric = u->mass_error != 0.0 || u->inertia_error != 0.0 || u->com_error_m != 0.0;
    for (int j = 0; j < a->n; ++j) {
        a->torque_limit[j] = a->model->actuator_ctrlrange[2 * j + 1];
        /* Joint friction the nominal model lacks, in MuJoCo's own terms and where the joint's own
         * is (the motor's side): damping is integrated implicitly and frictionloss is a constraint
         * (it sticks), both stable at a 1 ms step on a 1e-4 kg m^2 wrist, where an explicit
         * -b qd - c tanh(qd / eps) blew up at b = 3. */
        a->model->dof_damping[a->motor_dof[j]] += u->viscous[j];
        a->model->dof_frictionloss[a->motor_dof[j]] += u->coulomb[j];
    }
    for (int t = 0; t < a->model->ntendon; ++t) a->model->tendon_stiffness[t] *= u->gear_stiffness_scale;
    /* The draws come in a fixed order, each only when asked for: the signal's first two knots,
     * the links' parametric errors, the payload (one seed, one arm). */
    sim_rng_seed(&a->rng, u->seed);
    if (u->paper_ratio != 0.0) {
        draw_knot(a, a->knots[0]);
        draw_knot(a, a->knots[1]);
    }
    perturb(a);
    a->payload_kg = u->payload_kg[1] > u->payload_kg[0] ? sim_rng_uniform(&a->rng, u->payload_kg[0], u->payload_kg[1])
                                                        : u->payload_kg[0];
    if (a->payload_kg > 0.0 && add_payload(a, a->payload_kg, err, errcap) != 0) {
        sim_arm_close(a);
        return -1;
    }
    a->nominal_differs = a->parametric || a->payload_kg > 0.0;
    a->w_from_true_arm = w_from_true_arm(a);
    a->w_from_plant = w_from_flexible_plant(a);
    a->data = mj_makeData(a->model);
    a->nominal_data = mj_makeData(a->nominal);
    if (a->data == NULL || a->nominal_data == NULL) {
        snprintf(err, errcap, "--model: '%s': MuJoCo could not allocate its data", path);
        sim_arm_close(a);
        return -1;
    }
    mj_setConst(a->model, a->data); /* the masses changed: what MuJoCo derived from them, anew */
    const int key = mj_name2id(a->model, mjOBJ_KEY, keyframe);
    if (key < 0) {
        snprintf(err, errcap, "--model: '%s' has no keyframe '%s'", true_path, keyframe);
        sim_arm_close(a);
        return -1;
    }
    mj_resetDataKeyframe(a->model, a->data, key);
    if (a->flexible) {
        wind_up_gears(a);
    } else {
        mj_forward(a->model, a->data);
    }
    remember_joints(a);
    return 0;
}

int sim_arm_set_pose(sim_arm_t *a, const double *q, char *err, size_t errcap)
{
    const mjModel *m = a->model;
    for (int j = 0; j < a->n; ++j) {
        const int jnt = m->dof_jntid[j];
        const int limited = m->jnt_limited[jnt];
        const double lo = m->jnt_range[2 * jnt], hi = m->jnt_range[2 * jnt + 1];
        if (!isfinite(q[j]) || (limited && (q[j] < lo || q[j] > hi))) {
            snprintf(err, errcap, "--start-pose: joint %d ('%s'): %g rad is outside its range [%g, %g]", j + 1,
                     mj_id2name(m, mjOBJ_JOINT, jnt) ? mj_id2name(m, mjOBJ_JOINT, jnt) : "?", q[j], lo, hi);
            return -1;
        }
    }
    mjData *d = a->data;
    for (int v = 0; v < m->nv; ++v) d->qvel[v] = 0.0;
    for (int j = 0; j < a->n; ++j) {
        d->qpos[j] = q[j];
        if (a->motor_qpos[j] != j) d->qpos[a->motor_qpos[j]] = q[j];
    }
    if (a->flexible) {
        wind_up_gears(a);
    } else {
        mj_forward(m, d);
    }
    remember_joints(a);
    return 0;
}

/* What a brake changes and a drive's velocity loop is tuned for, per joint, before any brake acts. */
static void remember_joints(sim_arm_t *a)
{
    const mjModel *m = a->model;
    const int nv = (int)m->nv;
    mj_fullM(m, a->data, a->mass_full);
    for (int j = 0; j < a->n; ++j) {
        const int v = a->motor_dof[j];
        a->own_frictionloss[j] = m->dof_frictionloss[v];
        memcpy(a->own_solref[j], m->dof_solref + mjNREF * v, sizeof(a->own_solref[j]));
        memcpy(a->own_solimp[j], m->dof_solimp + mjNIMP * v, sizeof(a->own_solimp[j]));
        a->brake_nm[j] = 0.0;
        a->drive_inertia[j] = a->mass_full[v * nv + v] + (v != j ? a->mass_full[j * nv + j] : 0.0);
    }
}

/* A brake's constraint: stiff (a time constant of two steps, impedance near 1), where MuJoCo's
 * default (0.02 s, 0.9..0.95) lets a 62 N m load creep 1.6 deg in 2 s through a 150 N m brake. */
#define BRAKE_SOLREF_TIMESTEPS 2.0
static const double k_brake_solimp[mjNIMP] = {0.99, 0.999, 0.001, 0.5, 2.0};

void sim_arm_set_brake(sim_arm_t *a, int j, double holding_nm)
{
    if (j < 0 || j >= a->n || holding_nm == a->brake_nm[j]) return;
    mjModel *m = a->model;
    const int v = a->motor_dof[j];
    a->brake_nm[j] = holding_nm;
    m->dof_frictionloss[v] = a->own_frictionloss[j] + holding_nm;
    if (holding_nm > 0.0) {
        m->dof_solref[mjNREF * v] = BRAKE_SOLREF_TIMESTEPS * m->opt.timestep;
        m->dof_solref[mjNREF * v + 1] = 1.0;
        memcpy(m->dof_solimp + mjNIMP * v, k_brake_solimp, sizeof(k_brake_solimp));
    } else {
        memcpy(m->dof_solref + mjNREF * v, a->own_solref[j], sizeof(a->own_solref[j]));
        memcpy(m->dof_solimp + mjNIMP * v, a->own_solimp[j], sizeof(a->own_solimp[j]));
    }
}

double sim_arm_motor_q(const sim_arm_t *a, int j)
{
    return a->data->qpos[a->motor_qpos[j]];
}

double sim_arm_motor_qd(const sim_arm_t *a, int j)
{
    return a->data->qvel[a->motor_dof[j]];
}

/* d(t): 2n channels, linear between knots every knot_s seconds (time only moves forward). */
static void signal_at(sim_arm_t *a, double t, double *out)
{
    const double knot_s = a->unc.paper_knot_s;
    const double k = sim_py_floordiv(t, knot_s);
    while ((double)a->knot_index < k) {
        memcpy(a->knots[0], a->knots[1], sizeof(a->knots[0]));
        draw_knot(a, a->knots[1]);
        a->knot_index++;
    }
    const double frac = t / knot_s - k;
    for (int i = 0; i < 2 * a->n; ++i) {
        out[i] = (1.0 - frac) * a->knots[0][i] + frac * a->knots[1][i];
    }
}

/* The generalized force that makes MuJoCo integrate the uncertain dynamics: with M, V of the
 * (parametrically perturbed) arm, the true acceleration is qdd = (M + M~)^-1 (tau + tau_f - V - V~);
 * returned is f with M qdd + V = tau + f. */
static void extra_force(sim_arm_t *a, double t, const double *bias, const double *tau, double *f)
{
    const int n = a->n;
    if (a->unc.paper_ratio == 0.0) {
        memset(f, 0, (size_t)n * sizeof(double));
        return;
    }
    double dd[2 * SIM_MAX_JOINTS];
    signal_at(a, t, dd);
    const double *d = dd;
    const double *dv = dd + n;
    double m_true[SIM_MAX_JOINTS * SIM_MAX_JOINTS];
    double rhs[SIM_MAX_JOINTS];
    double qdd[SIM_MAX_JOINTS];
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
            const double mij = a->mass[i * n + j];
            m_true[i * n + j] = mij + 0.5 * (d[i] * mij + mij * d[j]);
        }
        rhs[i] = tau[i] - bias[i] * (1.0 + dv[i]);
    }
    mju_cholFactor(m_true, n, 0.0);
    mju_cholSolve(qdd, m_true, rhs, n);
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int j = 0; j < n; ++j) {
            s += a->mass[i * n + j] * qdd[j];
        }
        f[i] = s + bias[i] - tau[i];
    }
}

/* MuJoCo's force on each dof from joint motors under `ctrl` (its fwdActuation for the motors
 * w_from_true_arm admits: control and force clamped, per-joint actuator force limits). */
static void motor_force(const mjModel *m, const double *ctrl, double *qfrc)
{
    memset(qfrc, 0, (size_t)m->nv * sizeof(double));
    const int clamp_ctrl = (m->opt.disableflags & mjDSBL_CLAMPCTRL) == 0;
    for (int i = 0; i < m->nu; ++i) {
        double c = ctrl[i];
        if (clamp_ctrl && m->actuator_ctrllimited[i]) c = mju_clip(c, m->actuator_ctrlrange[2 * i], m->actuator_ctrlrange[2 * i + 1]);
        double f = m->actuator_gainprm[i * mjNGAIN] * c;
        if (m->actuator_forcelimited[i]) f = mju_clip(f, m->actuator_forcerange[2 * i], m->actuator_forcerange[2 * i + 1]);
        qfrc[m->jnt_dofadr[m->actuator_trnid[2 * i]]] += m->actuator_gear[6 * i] * f;
    }
    for (int j = 0; j < m->njnt; ++j) {
        if (m->jnt_actfrclimited[j]) {
            const int v = m->jnt_dofadr[j];
            qfrc[v] = mju_clip(qfrc[v], m->jnt_actfrcrange[2 * j], m->jnt_actfrcrange[2 * j + 1]);
        }
    }
}

/* w = nominal minus true acceleration at the step's start, from the true arm's step alone. The
 * nominal model is the true one without constraints, springs (none here) and the added viscous
 * friction, and without the extra force; so its acceleration is the true unconstrained one plus
 * M^-1 (viscous qd - extra force + commanded motor force - applied motor force). */
static void w_from_true_step(sim_arm_t *a, const double *tau_commanded, const double *qvel_start, double *w)
{
    const mjModel *m = a->model;
    mjData *d = a->data;
    double y[SIM_MAX_JOINTS], x[SIM_MAX_JOINTS];
    motor_force(m, tau_commanded, y);
    for (int v = 0; v < m->nv; ++v) {
        y[v] += a->unc.viscous[v] * qvel_start[v] - d->qfrc_applied[v] - d->qfrc_actuator[v];
    }
    mj_solveM(m, d, x, y, 1);
    for (int v = 0; v < m->nv; ++v) {
        w[v] = d->qacc_smooth[v] + x[v] - d->qacc[v];
    }
}

/* The first MuJoCo step of a period, and w from a forward pass of the nominal model. */
static void nominal_step_start(sim_arm_t *a, const double *tau, const double *tau_commanded, double *w)
{
    const int n = a->n;
    mjData *d = a->data;
    mjData *nd = a->nominal_data;
    memcpy(nd->qpos, d->qpos, (size_t)a->nominal->nq * sizeof(double));
    memcpy(nd->qvel, d->qvel, (size_t)n * sizeof(double));
    memcpy(nd->ctrl, tau_commanded != NULL ? tau_commanded : tau, (size_t)n * sizeof(double));
    mj_forward(a->nominal, nd);
    if (a->unc.paper_ratio != 0.0) {
        /* M and V of the true arm at the step's start. Without parametric error the true arm's
         * are the nominal one's, just computed: no second forward pass. */
        const mjModel *sm = a->nominal;
        const mjData *sd = nd;
        if (a->parametric) {
            mj_forward(a->model, d);
            sm = a->model;
            sd = d;
        }
        mj_fullM(sm, sd, a->mass);
        extra_force(a, (double)a->step_count * a->period, sd->qfrc_bias, tau, d->qfrc_applied);
    } else {
        extra_force(a, 0.0, d->qfrc_bias, tau, d->qfrc_applied);
    }
    mj_step(a->model, d); /* qacc is the acceleration at the step's start */
    for (int j = 0; j < n; ++j) {
        w[j] = nd->qacc[j] - d->qacc[j];
    }
}

/* The links' mass matrix: the plant's link block (with rotors the plant's is larger). */
static void link_mass(sim_arm_t *a)
{
    const int n = a->n, nv = (int)a->model->nv;
    if (nv == n) {
        mj_fullM(a->model, a->data, a->mass);
        return;
    }
    mj_fullM(a->model, a->data, a->mass_full);
    for (int i = 0; i < n; ++i) memcpy(a->mass + i * n, a->mass_full + i * nv, (size_t)n * sizeof(double));
}

/* The nominal model's acceleration under the commanded torque, from the plant at the step's start
 * (after mj_step1; w_from_flexible_plant says when it is the nominal model's forward pass's): its
 * links' M (a->mass, link_mass) with the links' armature, their bias, the nominal damping. */
static void nominal_acc_from_plant(const sim_arm_t *a, const double *commanded, const double *qvel_start, double *acc)
{
    const int n = a->n;
    const mjModel *nm = a->nominal;
    double mass[SIM_MAX_JOINTS * SIM_MAX_JOINTS], force[SIM_MAX_JOINTS], rhs[SIM_MAX_JOINTS];
    memcpy(mass, a->mass, (size_t)(n * n) * sizeof(double));
    for (int j = 0; j < n; ++j) mass[j * n + j] += nm->dof_armature[j] - a->model->dof_armature[j];
    motor_force(nm, commanded, force);
    for (int j = 0; j < n; ++j) rhs[j] = force[j] - a->data->qfrc_bias[j] - nm->dof_damping[j] * qvel_start[j];
    mju_cholFactor(mass, n, 0.0);
    mju_cholSolve(acc, mass, rhs, n);
}

/* A period's first step of the arm with flexible joints: the paper's uncertainty acts on the links
 * (their drive is the gear's spring and damper on a flexible joint, the motor on a rigid one); w
 * from the plant's own step where it can (w_from_plant), else from a forward pass of the nominal
 * model at the step's start. */
static void flexible_step_start(sim_arm_t *a, const double *tau, const double *tau_commanded, double *w)
{
    const int n = a->n;
    mjData *d = a->data;
    mjData *nd = a->nominal_data;
    const double *commanded = tau_commanded != NULL ? tau_commanded : tau;
    double nominal[SIM_MAX_JOINTS], qvel_start[SIM_MAX_JOINTS];
    if (!a->w_from_plant) {
        memcpy(nd->qpos, d->qpos, (size_t)n * sizeof(double));
        memcpy(nd->qvel, d->qvel, (size_t)n * sizeof(double));
        memcpy(nd->ctrl, commanded, (size_t)n * sizeof(double));
        mj_forward(a->nominal, nd);
        memcpy(nominal, nd->qacc, (size_t)n * sizeof(double));
    }
    memcpy(qvel_start, d->qvel, (size_t)n * sizeof(double));
    mj_step1(a->model, d); /* M, bias and the gears' forces at the step's start */
    if (a->unc.paper_ratio != 0.0 || a->w_from_plant) link_mass(a);
    if (a->w_from_plant) nominal_acc_from_plant(a, commanded, qvel_start, nominal);
    if (a->unc.paper_ratio != 0.0) {
        double drive[SIM_MAX_JOINTS];
        for (int j = 0; j < n; ++j) drive[j] = a->motor_dof[j] != j ? d->qfrc_passive[j] : tau[j];
        extra_force(a, (double)a->step_count * a->period, d->qfrc_bias, drive, d->qfrc_applied);
    }
    mj_step2(a->model, d);
    for (int j = 0; j < n; ++j) {
        w[j] = nominal[j] - d->qacc[j];
    }
}

int sim_arm_step(sim_arm_t *a, const double *tau, const double *tau_commanded, double *w)
{
    const int bad_before = a->data->warning[mjWARN_BADQACC].number;
    const int n = a->n;
    mjData *d = a->data;
    memcpy(d->ctrl, tau, (size_t)n * sizeof(double));
    if (a->flexible) {
        flexible_step_start(a, tau, tau_commanded, w);
    } else if (a->w_from_true_arm) {
        double qvel_start[SIM_MAX_JOINTS];
        memcpy(qvel_start, d->qvel, (size_t)n * sizeof(double));
        mj_step1(a->model, d); /* M and V of the arm at the step's start; the nominal model's too */
        if (a->unc.paper_ratio != 0.0) {
            mj_fullM(a->model, d, a->mass);
            extra_force(a, (double)a->step_count * a->period, d->qfrc_bias, tau, d->qfrc_applied);
        } else {
            extra_force(a, 0.0, d->qfrc_bias, tau, d->qfrc_applied);
        }
        mj_step2(a->model, d);
        w_from_true_step(a, tau_commanded != NULL ? tau_commanded : tau, qvel_start, w);
    } else {
        nominal_step_start(a, tau, tau_commanded, w);
    }
    for (int k = 1; k < a->substeps; ++k) { /* the rest of the period: the same torque, the force anew */
        double drive[SIM_MAX_JOINTS];
        for (int j = 0; j < n; ++j) drive[j] = a->motor_dof[j] != j ? d->qfrc_passive[j] : tau[j];
        extra_force(a, ((double)a->step_count + (double)k / a->substeps) * a->period, d->qfrc_bias, drive,
                    d->qfrc_applied);
        mj_step(a->model, d);
    }
    a->step_count++;
    if (d->warning[mjWARN_BADQACC].number == bad_before) return 0;
    /* the dof MuJoCo named: a rotor's stands for its joint */
    const int dof = d->warning[mjWARN_BADQACC].lastinfo;
    for (int j = 0; j < n; ++j) {
        if (a->motor_dof[j] == dof) return j + 1;
    }
    return dof < n ? dof + 1 : 1;
}

void sim_arm_diverged_text(const sim_arm_t *a, int dof, unsigned long long periods, char *out, unsigned long cap)
{
    snprintf(out, cap,
             "the simulation diverged at t = %.3f s (period %llu): MuJoCo found a NaN, infinite or huge "
             "acceleration at joint %d and reset the arm; drives faulted, torque off",
             (double)a->step_count * a->period, periods, dof);
}

void sim_arm_close(sim_arm_t *a)
{
    if (a->data != NULL) mj_deleteData(a->data);
    if (a->nominal_data != NULL) mj_deleteData(a->nominal_data);
    if (a->model != NULL) mj_deleteModel(a->model);
    if (a->nominal != NULL) mj_deleteModel(a->nominal);
    a->data = a->nominal_data = NULL;
    a->model = a->nominal = NULL;
}
