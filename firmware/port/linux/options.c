#include "options.h"

#include "arm/can_bus_config.h"
#if !ARM_PORT_MCU
#include "arm/lcm_url.h"
#endif

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/methods.h"
#include "argv_table.h"
#include "canopen_text.h"
#include "task.h"
#if !ARM_PORT_MCU
#include "traj_file.h"
#endif

/* "pd | pm | ..." from the method table (arm/methods.h): the one list of methods. */
static const char *method_list(const char *sep)
{
    static char list[256];
    size_t len = 0;
    list[0] = '\0';
    for (int m = 0; m < (int)ARM_METHOD_COUNT && len < sizeof(list); ++m) {
        len += (size_t)snprintf(list + len, sizeof(list) - len, "%s%s", m ? sep : "",
                                arm_method_ops((arm_method_t)m)->name);
    }
    return list;
}

void options_usage(const char *prog)
{
    printf("usage: %s [options]\n", prog);
    printf(ARM_CONTROLLER_USAGE, ARM_CAN_BUS_SET_MAX, method_list(" | "));
}

/* "all", "none" or a comma-separated list of range, velocity, step, following, torque. */
static int parse_checks(const char *v, uint32_t *out, char *err, unsigned long errcap)
{
    static const struct { const char *name; uint32_t bit; } k[] = {
        {"range", ARM_CHECK_POSITION_RANGE}, {"velocity", ARM_CHECK_VELOCITY}, {"step", ARM_CHECK_POSITION_STEP},
        {"following", ARM_CHECK_FOLLOWING_ERROR}, {"torque", ARM_CHECK_TORQUE}};
    if (strcmp(v, "all") == 0) {
        *out = ARM_CHECK_ALL;
        return 0;
    }
    if (strcmp(v, "none") == 0) {
        *out = 0u;
        return 0;
    }
    uint32_t m = 0u;
    const char *p = v;
    while (*p != '\0') {
        const char *end = strchr(p, ',');
        const size_t len = end ? (size_t)(end - p) : strlen(p);
        uint32_t bit = 0u;
        for (size_t i = 0; i < sizeof(k) / sizeof(k[0]); ++i) {
            if (strlen(k[i].name) == len && strncmp(p, k[i].name, len) == 0) bit = k[i].bit;
        }
        if (bit == 0u) {
            snprintf(err, errcap, "--checks: '%s' is not all, none or a list of range, velocity, step, following, torque", v);
            return -1;
        }
        m |= bit;
        p = end ? end + 1 : p + len;
    }
    *out = m;
    return 0;
}

/* "a,b,c,..." with exactly ARM_N_JOINTS numbers in [lo, hi]. */
static int parse_list(const char *name, const char *s, double lo, double hi, float out[ARM_N_JOINTS],
                      char *err, unsigned long errcap)
{
    const char *p = s;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        char *end = NULL;
        errno = 0;
        const double v = strtod(p, &end);
        const char want = j + 1 < ARM_N_JOINTS ? ',' : '\0';
        if (errno != 0 || end == p || *end != want || !isfinite(v) || v < lo || v > hi) {
            snprintf(err, errcap, "%s: '%s' is not %d comma-separated numbers in [%g, %g]", name, s,
                     ARM_N_JOINTS, lo, hi);
            return -1;
        }
        out[j] = (float)v;
        p = end + 1;
    }
    return 0;
}

static int check_lcm_url(const char *url, char *err, unsigned long errcap)
{
#if ARM_PORT_MCU /* the MCU image publishes nothing itself: its bridge does, and checks the URL */
    (void)url;
    (void)err;
    (void)errcap;
    return 0;
#else
    /* The multicast rule: telemetry never leaves this host (TTL exactly 0, the group on lo). */
    arm_lcm_url_t u;
    if (arm_lcm_url_parse(url, "--lcm-url", &u, err, errcap) != 0) {
        return -1;
    }
    return arm_lcm_url_check_route(&u, "--lcm-url", err, errcap);
#endif
}

/* The special options' handlers (the registry's type "special"): target is the options_t. */
typedef struct {
    int bus_given;
} parse_ctx_t;

static int opt_bus(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    parse_ctx_t *ctx = c;
    if (!ctx->bus_given) {
        arm_can_bus_set_config_init(&opt->buses);
        opt->bus[0] = '\0';
        ctx->bus_given = 1;
    }
    if (arm_can_bus_set_add(&opt->buses, v, ARM_N_JOINTS, o->name, err, errcap) != 0) return -1;
    const size_t len = strlen(opt->bus);
    snprintf(opt->bus + len, sizeof(opt->bus) - len, "%s%s", len ? " " : "", v);
    return 0;
}

static int opt_lcm_url(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
    if (argv_copy(o->name, v, opt->lcm_url, sizeof(opt->lcm_url), err, errcap) != 0) return -1;
    return check_lcm_url(v, err, errcap);
}

static int opt_design_file(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
#if ARM_PM_RUNTIME_DESIGNS
    (void)o;
    if (design_file_load(v, &opt->design, err, errcap) != 0) return -1;
    opt->ctl.design = &opt->design.d;
    return 0;
#else
    (void)opt;
    snprintf(err, errcap, "%s %s: this firmware runs the design built into it alone (ARM_PM_RUNTIME_DESIGNS 0)", o->name, v);
    return -1;
#endif
}

static int opt_method(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
    const arm_method_t m = arm_method_from_str(v);
    if (m == ARM_METHOD_COUNT) {
        snprintf(err, errcap, "%s: unknown method '%s' (known: %s)", o->name, v, method_list(", "));
        return -1;
    }
    opt->ctl.method = m;
    return 0;
}

static int opt_checks(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c;
    (void)o;
    return parse_checks(v, &((options_t *)t)->ctl.checks, err, errcap);
}

static int opt_safe_stop(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
    double d = 0.0;
    if (strncmp(v, "hold", 4) == 0 && (v[4] == ':' || v[4] == '\0')) {
        opt->ctl.safe_stop_rate = (float)ARM_P_SAFE_STOP_HOLD_RATE;
        if (v[4] == ':') {
            if (argv_double("--safe-stop hold rate", v + 5, 0.0, ARM_P_SAFE_STOP_HOLD_RATE_MAX, 0, &d, err, errcap) != 0) return -1;
            opt->ctl.safe_stop_rate = (float)d;
        }
        return 0;
    }
    snprintf(err, errcap, "%s: '%s' is not hold or hold:RATE (a stop holds a loaded arm: zero torque alone would drop it)",
             o->name, v);
    return -1;
}

static int opt_ref_amp(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c; /* the sign: which way it moves */
    return parse_list(o->name, v, ARM_P_CONTROLLER_REF_AMP_MIN, ARM_P_CONTROLLER_REF_AMP_MAX,
                      ((options_t *)t)->ref_amp, err, errcap);
}

static int opt_ref_freq(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c;
    return parse_list(o->name, v, ARM_P_CONTROLLER_REF_FREQ_MIN, ARM_P_CONTROLLER_REF_FREQ_MAX,
                      ((options_t *)t)->ref_freq_hz, err, errcap);
}

static int opt_rt(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c;
    return rt_option_parse(o->name, v, &((options_t *)t)->rt, err, errcap);
}

/* --node: the k-th is joint k's drive (gen/drives.py's table of the arm). */
static int opt_node(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
    if (opt->n_nodes >= ARM_N_JOINTS) {
        snprintf(err, errcap, "%s '%s': more than one per joint (%d joints)", o->name, v, ARM_N_JOINTS);
        return -1;
    }
    if (canopen_parse_node(v, &opt->node[opt->n_nodes], err, errcap) != 0) return -1;
    if (opt->node[opt->n_nodes].joint_torque_limit_nm > 0.0f) {
        /* the drive is checked against the controller's own limit, the arm's (arm_canopen_boot takes limit=) */
        snprintf(err, errcap, "%s '%s': limit: the joint's torque limit is the arm's, not an option here", o->name, v);
        return -1;
    }
    if (opt->node[opt->n_nodes].node_id != opt->n_nodes + 1u) {
        /* heartbeats, EMCY and the PDOs' COB-IDs are matched to joints by the drive number */
        snprintf(err, errcap, "%s '%s': joint %u's node id must be its drive number %u", o->name, v,
                 opt->n_nodes + 1u, opt->n_nodes + 1u);
        return -1;
    }
    opt->n_nodes++;
    return 0;
}

static int opt_rpdo_type(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c;
    double d = 0.0;
    if (argv_double(o->name, v, 1.0, 255.0, 0, &d, err, errcap) != 0) return -1;
    if (d != floor(d) || (d > 240.0 && d < 254.0)) {
        snprintf(err, errcap, "%s '%s': a CiA 301 transmission type, 1..240, 254 or 255", o->name, v);
        return -1;
    }
    ((options_t *)t)->rpdo_type = (uint8_t)d;
    return 0;
}

static int opt_tpdo2_type(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c;
    double d = 0.0;
    if (argv_double(o->name, v, 1.0, 240.0, 0, &d, err, errcap) != 0) return -1;
    if (d != floor(d)) {
        snprintf(err, errcap, "%s '%s': a synchronous transmission type, 1..240 (every N-th SYNC)", o->name, v);
        return -1;
    }
    ((options_t *)t)->tpdo2_type = (uint8_t)d;
    return 0;
}

/* --jog J:RAD: joint J (1-based) by RAD. */
static int opt_jog(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
    char *end = NULL;
    errno = 0;
    const long j = strtol(v, &end, 10);
    double rad = 0.0;
    if (errno != 0 || end == v || *end != ':' || j < 1 || j > ARM_N_JOINTS) {
        snprintf(err, errcap, "%s: '%s' is not J:RAD with J a joint 1..%d", o->name, v, ARM_N_JOINTS);
        return -1;
    }
    if (argv_double(o->name, end + 1, ARM_P_CONTROLLER_JOG_MIN, ARM_P_CONTROLLER_JOG_MAX, 0, &rad, err, errcap) != 0) {
        return -1;
    }
    opt->jog_joint = (int)j - 1;
    opt->jog_rad = (float)rad;
    return 0;
}

static int opt_trajectory(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
#if ARM_PORT_MCU
    (void)opt;
    snprintf(err, errcap, "%s %s: the MCU image has no file to read", o->name, v);
    return -1;
#else
    if (argv_copy(o->name, v, opt->trajectory_path, sizeof(opt->trajectory_path), err, errcap) != 0) return -1;
    return traj_file_load(v, &opt->trajectory, err, errcap);
#endif
}

static int opt_stream_url(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    options_t *opt = t;
    (void)c;
    if (argv_copy(o->name, v, opt->stream_url, sizeof(opt->stream_url), err, errcap) != 0) return -1;
    return check_lcm_url(v, err, errcap);
}

static int opt_commission_pulse(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)c;
    return parse_list(o->name, v, ARM_P_CONTROLLER_COMMISSION_PULSE_MIN, ARM_P_CONTROLLER_COMMISSION_PULSE_MAX,
                      ((options_t *)t)->commission_pulse, err, errcap);
}

#define ROW(...) ARGV_ROW(options_t, __VA_ARGS__)
static const argv_opt_t k_options[] = {ARM_CONTROLLER_OPTIONS(ROW, ARGV_SPECIAL_ROW)};
enum { ARM_CONTROLLER_OPTIONS(ARGV_ID, ARGV_ID) ARGV_COUNT };

int options_parse(int argc, char **argv, const arm_robot_model_t *model, options_t *opt, char *err,
                  unsigned long errcap)
{
    memset(opt, 0, sizeof(*opt));
    arm_ctl_default_config(model, &opt->ctl);
    rt_options_default(&opt->rt);
    argv_defaults(k_options, ARGV_COUNT, opt);
    strcpy(opt->bus, ARM_P_CONTROLLER_BUS_DEFAULT);
    arm_can_bus_set_config_init(&opt->buses);
    if (arm_can_bus_set_add(&opt->buses, opt->bus, ARM_N_JOINTS, "--bus", err, errcap) != 0) {
        return -1;
    }
    strcpy(opt->lcm_url, ARM_P_CONTROLLER_LCM_URL_DEFAULT);
    strcpy(opt->stream_url, ARM_P_CONTROLLER_STREAM_URL_DEFAULT);
    opt->jog_joint = -1;
    parse_ctx_t ctx = {0};
    unsigned char given[ARGV_COUNT];
    const int rc = argv_parse(argc, argv, k_options, ARGV_COUNT, opt, &ctx, given, err, errcap);
    if (rc == 1) {
        options_usage(argv[0]);
        return 1;
    }
    if (rc != 0) {
        return -1;
    }
    if (arm_can_bus_set_check(&opt->buses, ARM_N_JOINTS, "--bus", err, errcap) != 0) {
        return -1;
    }
    if (given[ARGV_OPT_REF_AMP] != given[ARGV_OPT_REF_FREQ]) {
        snprintf(err, errcap, "--ref-amp and --ref-freq go together (one was given without the other)");
        return -1;
    }
    if (opt->n_nodes != 0u && (opt->n_nodes != ARM_N_JOINTS || !opt->protocol_canopen)) {
        snprintf(err, errcap, "--node: %u given: one per joint (%d), with --protocol canopen", opt->n_nodes,
                 ARM_N_JOINTS);
        return -1;
    }
    opt->ref_given = given[ARGV_OPT_REF_AMP];
    if (opt->ctl.design == &opt->design.d && arm_pm_check_design(opt->ctl.design, (float)opt->rate_hz) != 0) {
        snprintf(err, errcap, "--design-file %s: loop_rate_hz: the design was discretised for %g Hz, this run's --rate is %g Hz",
                 opt->design.path, (double)opt->design.d.loop_rate_hz, opt->rate_hz);
        return -1;
    }
    /* The margin and the mismatch fraction are per arm: in the joints' units here (the defaults
     * give what arm_ctl_default_config gave). */
    arm_ctl_joint_range(model, (float)opt->position_margin_rad, opt->ctl.q_min, opt->ctl.q_max);
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        opt->ctl.torque_mismatch_limit[j] = (float)opt->torque_mismatch * model->link[j].torque_limit;
    }
    const float default_period = opt->ctl.period_s;
    opt->ctl.period_s = (float)(1.0 / opt->rate_hz);
    if (!given[ARGV_OPT_TORQUE_RATE_LIMIT]) {
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            opt->ctl.torque_rate_limit[j] *= opt->ctl.period_s / default_period;
        }
    }
    const double steps = floor((opt->ref_hold_s + opt->duration_s) * opt->rate_hz + 0.5);
    if (steps < 1.0 || steps > 4e9) {
        snprintf(err, errcap, "--duration x --rate gives %.0f periods; need 1..4e9", steps);
        return -1;
    }
    opt->steps = (uint32_t)steps;
    return task_check_options(opt, given[ARGV_OPT_JOG], given[ARGV_OPT_TRAJECTORY], err, errcap);
}
