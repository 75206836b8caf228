#define _GNU_SOURCE
#include "sim_options.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <stddef.h>
#include <string.h>

#include "arm/lcm_url.h"
#include "argv_table.h"

#ifndef ARM_SIM_DEFAULT_MODEL
#define ARM_SIM_DEFAULT_MODEL "host_sim/models/ur5e_arm.xml"
#endif

static void usage(const char *prog)
{
    printf("usage: %s [options]\n"
           "The simulated arm and its emulated CiA 402 drives on the CAN bus (tools/armctl hil starts it).\n",
           prog);
    printf(ARM_SIMULATOR_USAGE, ARM_CAN_BUS_SET_MAX, ARM_SIM_DEFAULT_MODEL);
}

static int parse_list(const char *name, const char *s, double lo, double hi, double *out, int *count, char *err,
                      unsigned long errcap)
{
    const char *p = s;
    int k = 0;
    for (;;) {
        char *end = NULL;
        errno = 0;
        const double v = strtod(p, &end);
        if (errno != 0 || end == p || !isfinite(v) || v < lo || v > hi || k >= SIM_MAX_JOINTS ||
            (*end != ',' && *end != '\0')) {
            snprintf(err, errcap, "%s: '%s' is not a list of up to %d numbers in [%g, %g]", name, s, SIM_MAX_JOINTS,
                     lo, hi);
            return -1;
        }
        out[k++] = v;
        if (*end == '\0') break;
        p = end + 1;
    }
    *count = k;
    return 0;
}

/* "I=REST": bus index I (0-based, below the bus limit) and the rest. */
static int bus_indexed(const char *name, const char *v, unsigned *index, const char **rest, char *err,
                       unsigned long errcap)
{
    char *end = NULL;
    const unsigned long i = strtoul(v, &end, 10);
    if (end == v || *end != '=' || i >= ARM_CAN_BUS_SET_MAX) {
        snprintf(err, errcap, "%s: '%s' is not I=VALUE with a bus index I in 0..%u", name, v,
                 ARM_CAN_BUS_SET_MAX - 1u);
        return -1;
    }
    *index = (unsigned)i;
    *rest = end + 1;
    return 0;
}

/* The special options' handlers (the registry's type "special"); target is the sim_options_t, ctx
 * the mask of buses given --frame-times. */
static int sim_bus(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    (void)c;
    if (o->n_bus_args == ARM_CAN_BUS_SET_MAX) {
        snprintf(err, errcap, "%s: at most %u buses", opt->name, ARM_CAN_BUS_SET_MAX);
        return -1;
    }
    return argv_copy(opt->name, v, o->bus_args[o->n_bus_args++], ARM_CAN_BUS_SPEC_MAX, err, errcap);
}

static int sim_lcm_url(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    arm_lcm_url_t u;
    (void)c;
    if (argv_copy(opt->name, v, o->lcm_url, sizeof(o->lcm_url), err, errcap) != 0) return -1;
    if (arm_lcm_url_parse(v, opt->name, &u, err, errcap) != 0) return -1;
    return arm_lcm_url_check_route(&u, opt->name, err, errcap);
}

static int sim_seed(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    char *end = NULL;
    (void)c;
    errno = 0;
    const unsigned long long s = strtoull(v, &end, 10);
    if (errno != 0 || end == v || *end != '\0' || v[0] == '-') {
        snprintf(err, errcap, "%s: '%s' is not a whole number in 0..2^64-1", opt->name, v);
        return -1;
    }
    ((sim_options_t *)t)->unc.seed = (uint64_t)s;
    return 0;
}

static int sim_viscous(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    (void)c;
    return parse_list(opt->name, v, ARM_P_SIMULATOR_VISCOUS_MIN, ARM_P_SIMULATOR_VISCOUS_MAX, o->unc.viscous,
                      &o->n_viscous, err, errcap);
}

static int sim_coulomb(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    (void)c;
    return parse_list(opt->name, v, ARM_P_SIMULATOR_COULOMB_MIN, ARM_P_SIMULATOR_COULOMB_MAX, o->unc.coulomb,
                      &o->n_coulomb, err, errcap);
}

/* --payload-kg M or M,MAX: a fixed payload, or one drawn uniform in [M, MAX] by the seed. */
static int sim_payload(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    double range[SIM_MAX_JOINTS];
    int k = 0;
    (void)c;
    if (parse_list(opt->name, v, ARM_P_SIMULATOR_PAYLOAD_KG_MIN, ARM_P_SIMULATOR_PAYLOAD_KG_MAX, range, &k, err,
                   errcap) != 0) {
        return -1;
    }
    if (k > 2 || (k == 2 && range[1] < range[0])) {
        snprintf(err, errcap, "%s: '%s' is not M or M,MAX with M <= MAX (kg)", opt->name, v);
        return -1;
    }
    o->unc.payload_kg[0] = range[0];
    o->unc.payload_kg[1] = k == 2 ? range[1] : range[0];
    return 0;
}

/* The per-bus options, I=VALUE: --frame-times (the frame lengths of bus I) and --bus-label. */
static int sim_bus_indexed(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_config_t *cfg = &((sim_options_t *)t)->cfg;
    unsigned b = 0;
    const char *rest = NULL;
    if (bus_indexed(opt->name, v, &b, &rest, err, errcap) != 0) return -1;
    if (strcmp(opt->name, "--bus-label") == 0) {
        return argv_copy(opt->name, rest, cfg->timelines[b].label, sizeof(cfg->timelines[b].label), err, errcap);
    }
    if (sim_timeline_parse_frames(&cfg->timelines[b], rest) != 0) {
        snprintf(err, errcap, "%s: '%s' is not I=ID:US,ID:US,... (11-bit ids, 0..1e6 us)", opt->name, v);
        return -1;
    }
    *(unsigned *)c |= 1u << b;
    return 0;
}

static int sim_lose_bus(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_config_t *cfg = &((sim_options_t *)t)->cfg;
    unsigned b = 0;
    unsigned long long from = 0;
    char tail = 0;
    (void)c;
    if (sscanf(v, "%u@%llu%c", &b, &from, &tail) != 2 || b >= ARM_CAN_BUS_SET_MAX) {
        snprintf(err, errcap, "%s: '%s' is not BUS@PERIOD (bus 0..%u)", opt->name, v, ARM_CAN_BUS_SET_MAX - 1u);
        return -1;
    }
    cfg->lose_bus = (int)b;
    cfg->lose_bus_from = from;
    return 0;
}

static int sim_late_answer(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_config_t *cfg = &((sim_options_t *)t)->cfg;
    unsigned long long first = 0, last = 0;
    int used = 0;
    (void)c;
    int parsed = v[0] != '-' && sscanf(v, "%llu-%llu:%n", &first, &last, &used) == 2 && used > 0;
    if (!parsed) {
        used = 0;
        parsed = v[0] != '-' && sscanf(v, "%llu:%n", &first, &used) == 1 && used > 0;
        last = first;
    }
    parsed = parsed && last >= first && last < INT64_MAX;
    const char *when = parsed ? v + used : "";
    if (parsed && strcmp(when, "command") == 0) {
        cfg->late_answer_release = SIM_LATE_AT_COMMAND;
    } else if (parsed && strcmp(when, "next-sync") == 0) {
        cfg->late_answer_release = SIM_LATE_AT_NEXT_SYNC;
    } else if (parsed && strcmp(when, "burst") == 0 && last - first < SIM_LATE_BURST_MAX) {
        cfg->late_answer_release = SIM_LATE_IN_ONE_BURST;
    } else {
        snprintf(err, errcap, "%s: '%s' is not PERIOD[-LAST]:command, PERIOD[-LAST]:next-sync or PERIOD[-LAST]:burst "
                 "(0 <= PERIOD <= LAST; a burst at most %u periods)", opt->name, v, SIM_LATE_BURST_MAX);
        return -1;
    }
    cfg->late_answer_period = (int64_t)first;
    cfg->late_answer_last = (int64_t)last;
    return 0;
}

static int sim_gear_ratio(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    unsigned long m = 0, sh = 0;
    char tail = 0;
    (void)c;
    if (sscanf(v, "%lu:%lu%c", &m, &sh, &tail) != 2 || m == 0u || sh == 0u || m > 0xFFFFFFFFul || sh > 0xFFFFFFFFul ||
        v[0] == '-') {
        snprintf(err, errcap, "%s: '%s' is not MOTOR:SHAFT (whole numbers >= 1)", opt->name, v);
        return -1;
    }
    o->co.preset.gear_motor = (uint32_t)m;
    o->co.preset.gear_shaft = (uint32_t)sh;
    return 0;
}

static int sim_inject_overcurrent(void *t, void *c, const argv_opt_t *opt, const char *v, char *err,
                                  unsigned long errcap)
{
    sim_options_t *o = t;
    unsigned node = 0;
    double at = 0.0;
    char tail = 0;
    (void)c;
    if (sscanf(v, "%u:%lf%c", &node, &at, &tail) != 2 || node < 1u || node > SIM_MAX_JOINTS || !isfinite(at) ||
        at < 0.0) {
        snprintf(err, errcap, "%s: '%s' is not NODE:TIME (node 1..%d, time >= 0 s)", opt->name, v, SIM_MAX_JOINTS);
        return -1;
    }
    o->co.overcurrent_node = (int)node;
    o->co.overcurrent_at_s = at;
    return 0;
}

/* --brake JOINT:HOLD:CLOSE:RELEASE: joint JOINT's holding brake (N m at the joint, ms, ms). */
static int sim_brake(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    unsigned joint = 0;
    double hold = 0.0, close_ms = 0.0, release_ms = 0.0;
    char tail = 0;
    (void)c;
    if (sscanf(v, "%u:%lf:%lf:%lf%c", &joint, &hold, &close_ms, &release_ms, &tail) != 4 || joint < 1u ||
        joint > SIM_MAX_JOINTS || !isfinite(hold) || hold <= 0.0 || hold > 1e6 || !isfinite(close_ms) ||
        close_ms < 0.0 || close_ms > 1e4 || !isfinite(release_ms) || release_ms < 0.0 || release_ms > 1e4) {
        snprintf(err, errcap, "%s: '%s' is not JOINT:HOLD:CLOSE:RELEASE (joint 1..%d, holding torque in (0, 1e6] N m, "
                 "delays 0..10000 ms)", opt->name, v, SIM_MAX_JOINTS);
        return -1;
    }
    o->cfg.brake[joint - 1u] = (sim_brake_config_t){hold, close_ms * 1e-3, release_ms * 1e-3};
    o->brake_given |= 1u << (joint - 1u);
    return 0;
}

static int sim_start_pose(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    (void)c;
    return parse_list(opt->name, v, -1e3, 1e3, o->start_pose, &o->n_start_pose, err, errcap);
}

static int node_u32(const char *s, uint32_t *out)
{
    char *end = NULL;
    errno = 0;
    const unsigned long long v = strtoull(s, &end, 10);
    if (errno != 0 || end == s || *end != '\0' || s[0] == '-' || v < 1u || v > 0xFFFFFFFFull) return -1;
    *out = (uint32_t)v;
    return 0;
}

/* --od FILE: the drives' object dictionary, gen/eds.py's table of their EDS or DCF. */
static int sim_od(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    static sim_co_table_t table;
    sim_options_t *o = t;
    (void)c;
    char why[600];
    if (sim_co_table_load(&table, v, why, sizeof(why)) != 0) {
        snprintf(err, errcap, "%s: %s (python -m gen.eds --eds FILE --table OUT writes one)", opt->name, why);
        return -1;
    }
    o->co.table = &table;
    return 0;
}

/* --node ID[,rated=N][,encoder=INC][,gear=M/S][,torque_unit=U][,efficiency=E][,quick_stop=N][,max=N]: node ID's
 * dictionary preset (0x6085 and 0x6072 too) and its gear's efficiency (arm_controller's --node syntax: the arm's drive table, python -m
 * gen.drives; its limit= and accept_no_master_watchdog= are the master's, and taken without effect here). */
static int sim_node(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_options_t *o = t;
    (void)c;
    char buf[256];
    if (strlen(v) >= sizeof(buf)) {
        snprintf(err, errcap, "%s '%.40s...': too long", opt->name, v);
        return -1;
    }
    strcpy(buf, v);
    char *save = NULL;
    char *tok = strtok_r(buf, ",", &save);
    uint32_t id = 0;
    if (tok == NULL || node_u32(tok, &id) != 0 || id > SIM_MAX_JOINTS) {
        snprintf(err, errcap, "%s '%s': the node id must be a drive, 1..%d", opt->name, v, SIM_MAX_JOINTS);
        return -1;
    }
    sim_co_preset_t *p = &o->co.node_preset[id - 1u];
    while ((tok = strtok_r(NULL, ",", &save)) != NULL) {
        char *eq = strchr(tok, '=');
        char *slash = eq != NULL ? strchr(eq, '/') : NULL;
        int bad = eq == NULL;
        if (!bad) *eq = '\0';
        if (bad) {
        } else if (strcmp(tok, "rated") == 0) {
            bad = node_u32(eq + 1, &p->rated_torque_mnm);
        } else if (strcmp(tok, "encoder") == 0) {
            bad = node_u32(eq + 1, &p->encoder_increments);
        } else if (strcmp(tok, "torque_unit") == 0) {
            bad = strcmp(eq + 1, "mNm") != 0 && strcmp(eq + 1, "uNm") != 0;
            p->torque_units_per_nm = strcmp(eq + 1, "uNm") == 0 ? 1000000u : 1000u;
        } else if (strcmp(tok, "quick_stop") == 0) {
            bad = node_u32(eq + 1, &p->quick_stop_decel);
        } else if (strcmp(tok, "max") == 0) { /* 0x6072 holds an INTEGER16's per-mille */
            bad = node_u32(eq + 1, &p->max_torque_permille) || p->max_torque_permille > 32767u;
        } else if (strcmp(tok, "gear") == 0 && slash != NULL) {
            *slash = '\0';
            bad = node_u32(eq + 1, &p->gear_motor) || node_u32(slash + 1, &p->gear_shaft);
        } else if (strcmp(tok, "efficiency") == 0 || strcmp(tok, "limit") == 0) {
            char *end = NULL;
            const double x = strtod(eq + 1, &end);
            bad = end == eq + 1 || *end != '\0' || !(x > 0.0 && x < 1e9) || (tok[0] == 'e' && x > 1.0);
            if (tok[0] == 'e') p->gear_efficiency = x;
        } else if (strcmp(tok, "accept_no_master_watchdog") == 0) {
            bad = strcmp(eq + 1, "true") != 0;
        } else {
            bad = 1;
        }
        if (bad) {
            snprintf(err, errcap, "%s '%s': expected ID[,rated=N][,encoder=INC][,gear=M/S][,torque_unit=mNm|uNm]"
                     "[,efficiency=E][,limit=NM][,accept_no_master_watchdog=true][,quick_stop=N][,max=1..32767], whole "
                     "numbers >= 1, 0 < E <= 1", opt->name, v);
            return -1;
        }
    }
    return 0;
}

/* The plant's per-joint lists (sim_plant.h): each into its own field of the truth. */
static int sim_truth_list(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_plant_truth_t *tr = &((sim_options_t *)t)->truth;
    (void)c;
    static const struct {
        const char *name;
        double lo, hi;
        size_t values, count;
    } k[] = {
        {"--rotor-inertia", ARM_P_SIMULATOR_ROTOR_INERTIA_MIN, ARM_P_SIMULATOR_ROTOR_INERTIA_MAX,
         offsetof(sim_plant_truth_t, rotor_inertia), offsetof(sim_plant_truth_t, n_rotor_inertia)},
        {"--joint-stiffness-scale", ARM_P_SIMULATOR_JOINT_STIFFNESS_SCALE_MIN, ARM_P_SIMULATOR_JOINT_STIFFNESS_SCALE_MAX,
         offsetof(sim_plant_truth_t, stiffness_scale), offsetof(sim_plant_truth_t, n_stiffness_scale)},
        {"--encoder-offset", ARM_P_SIMULATOR_ENCODER_OFFSET_MIN, ARM_P_SIMULATOR_ENCODER_OFFSET_MAX,
         offsetof(sim_plant_truth_t, encoder_offset), offsetof(sim_plant_truth_t, n_encoder_offset)},
        {"--gear-factor", ARM_P_SIMULATOR_GEAR_FACTOR_MIN, ARM_P_SIMULATOR_GEAR_FACTOR_MAX,
         offsetof(sim_plant_truth_t, gear_factor), offsetof(sim_plant_truth_t, n_gear_factor)},
    };
    for (size_t i = 0; i < sizeof(k) / sizeof(k[0]); ++i) {
        if (strcmp(opt->name, k[i].name) != 0) continue;
        return parse_list(opt->name, v, k[i].lo, k[i].hi, (double *)((char *)tr + k[i].values),
                          (int *)((char *)tr + k[i].count), err, errcap);
    }
    snprintf(err, errcap, "%s: not a plant option", opt->name);
    return -1;
}

/* --reversed-motor / --reversed-encoder J,..: joints 1..SIM_MAX_JOINTS as a mask. */
static int sim_truth_joints(void *t, void *c, const argv_opt_t *opt, const char *v, char *err, unsigned long errcap)
{
    sim_plant_truth_t *tr = &((sim_options_t *)t)->truth;
    double js[SIM_MAX_JOINTS];
    int n = 0;
    (void)c;
    if (parse_list(opt->name, v, 1.0, (double)SIM_MAX_JOINTS, js, &n, err, errcap) != 0) return -1;
    uint32_t mask = 0u;
    for (int i = 0; i < n; ++i) {
        if (js[i] != floor(js[i])) {
            snprintf(err, errcap, "%s: '%s' is not a list of joint numbers 1..%d", opt->name, v, SIM_MAX_JOINTS);
            return -1;
        }
        mask |= 1u << ((unsigned)js[i] - 1u);
    }
    if (strcmp(opt->name, "--reversed-motor") == 0) {
        tr->reversed_motor = mask;
    } else {
        tr->reversed_encoder = mask;
    }
    return 0;
}

#define ROW(...) ARGV_ROW(sim_options_t, __VA_ARGS__)
static const argv_opt_t k_options[] = {ARM_SIMULATOR_OPTIONS(ROW, ARGV_SPECIAL_ROW)};
enum { ARM_SIMULATOR_OPTIONS(ARGV_ID, ARGV_ID) ARGV_COUNT };

int sim_options_parse(int argc, char **argv, sim_options_t *o, char *err, unsigned long errcap)
{
    memset(o, 0, sizeof(*o));
    snprintf(o->model, sizeof(o->model), "%s", ARM_SIM_DEFAULT_MODEL);
    snprintf(o->keyframe, sizeof(o->keyframe), "%s", ARM_P_SIMULATOR_KEYFRAME_DEFAULT);
    snprintf(o->lcm_url, sizeof(o->lcm_url), "%s", ARM_P_SIMULATOR_LCM_URL_DEFAULT);
    sim_uncertainty_default(&o->unc);
    sim_servo_config_default(&o->cfg.servo);
    argv_defaults(k_options, ARGV_COUNT, o);
    o->cfg.lose_bus = -1;
    o->cfg.late_answer_period = -1;
    sim_config_t *c = &o->cfg;
    for (unsigned b = 0; b < ARM_CAN_BUS_SET_MAX; ++b) sim_timeline_init(&c->timelines[b]);
    unsigned frames_given = 0u;
    unsigned char given[ARGV_COUNT];
    const int prc = argv_parse(argc, argv, k_options, ARGV_COUNT, o, &frames_given, given, err, errcap);
    if (prc == 1) {
        usage(argv[0]);
        return 1;
    }
    if (prc != 0) return -1;
    o->co_given = given[ARGV_OPT_RATED_TORQUE_MNM] || given[ARGV_OPT_ENCODER_INCREMENTS] || given[ARGV_OPT_OD_GEAR_RATIO] ||
                  given[ARGV_OPT_INJECT_OVERCURRENT] || given[ARGV_OPT_NODE] || given[ARGV_OPT_OD];
    if (o->n_bus_args == 0u) {
        snprintf(o->bus_args[0], ARM_CAN_BUS_SPEC_MAX, "%s", ARM_P_SIMULATOR_BUS_DEFAULT);
        o->n_bus_args = 1u;
    }
    const unsigned want = (1u << o->n_bus_args) - 1u;
    if (c->timing != SIM_TIMING_OFF && (frames_given & want) != want) {
        snprintf(err, errcap, "--bus-timing %s: give --frame-times for every --bus (%u buses)",
                 c->timing == SIM_TIMING_VIRTUAL ? "virtual" : "wallclock", o->n_bus_args);
        return -1;
    }
    if (c->servo.position_noise_counts > 0.0 && c->servo.encoder_bits == 0) {
        snprintf(err, errcap, "--position-noise-counts: counts of what? give --encoder-bits too");
        return -1;
    }
    o->truth.serve = o->co.serve;
    o->co.sessions_path = o->sessions;
    const sim_plant_truth_t *tr = &o->truth;
    /* what the drives sense and act through (sim_canopen_loop.c): a start pose is any run's */
    const int drive_truth = tr->n_rotor_inertia || tr->n_stiffness_scale || tr->n_encoder_offset || tr->n_gear_factor ||
                            tr->reversed_motor || tr->reversed_encoder;
    if ((o->co.serve || o->sessions[0] != '\0' || drive_truth) &&
        o->protocol != SIM_PROTOCOL_CANOPEN) {
        snprintf(err, errcap, "--serve/--sessions and the plant's truth (--rotor-inertia, --encoder-offset, ...): "
                 "only with --protocol canopen");
        return -1;
    }
    if (o->sessions[0] != '\0' && !o->co.serve) {
        snprintf(err, errcap, "--sessions: with --serve");
        return -1;
    }
    if (o->co_given && o->protocol != SIM_PROTOCOL_CANOPEN) {
        snprintf(err, errcap, "--od/--rated-torque-mnm/--encoder-increments/--od-gear-ratio/--node/--inject-overcurrent: "
                 "only with --protocol canopen");
        return -1;
    }
    if (o->protocol == SIM_PROTOCOL_CANOPEN && c->timing == SIM_TIMING_WALLCLOCK) {
        snprintf(err, errcap, "--bus-timing wallclock: not with --protocol canopen (its drives' frames are timed "
                 "virtually, in lockstep: --bus-timing virtual)");
        return -1;
    }
    if ((c->servo.motor_encoder_bits > 0) != (c->servo.gear_ratio > 0.0)) {
        snprintf(err, errcap, "--motor-encoder-bits/--gear-ratio: give both (a motor encoder turns with the gear)");
        return -1;
    }
    if ((c->servo.position_source == SIM_ENCODER_MOTOR || c->servo.velocity_source == SIM_ENCODER_MOTOR) &&
        c->servo.motor_encoder_bits == 0) {
        snprintf(err, errcap, "--%s-source motor: give --motor-encoder-bits and --gear-ratio",
                 c->servo.position_source == SIM_ENCODER_MOTOR ? "position" : "velocity");
        return -1;
    }
    if (c->servo.velocity_source == SIM_ENCODER_MOTOR && c->servo.velocity_filter_hz == 0.0) {
        snprintf(err, errcap, "--velocity-source motor: give --velocity-filter-hz (without it the velocity is the true one)");
        return -1;
    }
    if (c->timing == SIM_TIMING_OFF && frames_given != 0u) {
        snprintf(err, errcap, "--frame-times: only with --bus-timing virtual|wallclock");
        return -1;
    }
    size_t len = 0;
    for (unsigned b = 0; b < o->n_bus_args; ++b) {
        len += (size_t)snprintf(c->bus_text + len, sizeof(c->bus_text) - len, "%s%s", b ? " " : "", o->bus_args[b]);
        if (len >= sizeof(c->bus_text)) break;
    }
    return 0;
}

int sim_options_finish(sim_options_t *o, sim_arm_t *arm, char *err, unsigned long errcap)
{
    const int n_joints = arm->n;
    if ((o->brake_given >> n_joints) != 0u) {
        snprintf(err, errcap, "--brake: joint %d: the arm has %d joints", 32 - __builtin_clz(o->brake_given), n_joints);
        return -1;
    }
    if (o->n_start_pose != 0) {
        if (o->n_start_pose != n_joints) {
            snprintf(err, errcap, "--start-pose: need %d values (one per joint of the model), got %d", n_joints,
                     o->n_start_pose);
            return -1;
        }
        if (sim_arm_set_pose(arm, o->start_pose, err, errcap) != 0) return -1;
    }
    arm_can_bus_set_config_init(&o->cfg.buses);
    for (unsigned b = 0; b < o->n_bus_args; ++b) {
        if (arm_can_bus_set_add(&o->cfg.buses, o->bus_args[b], (unsigned)n_joints, "--bus", err, errcap) != 0) {
            return -1;
        }
    }
    if (arm_can_bus_set_check(&o->cfg.buses, (unsigned)n_joints, "--bus", err, errcap) != 0) {
        return -1;
    }
    if ((o->n_viscous != 0 && o->n_viscous != n_joints) || (o->n_coulomb != 0 && o->n_coulomb != n_joints)) {
        snprintf(err, errcap, "--viscous/--coulomb: need %d values each (one per joint of the model), got %d and %d",
                 n_joints, o->n_viscous, o->n_coulomb);
        return -1;
    }
    return 0;
}
