#include "options.h"

#include "arm/can_bus.h"
#include "arm/lcm_url.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/methods.h"

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
    printf("  --bus SPEC[@DRIVES]     udp | udp:GROUP:PORT (python-can udp_multicast wire format,\n"
           "                          loopback only, TTL 0) | socketcan:IFACE; repeatable (up to 4\n"
           "                          buses), DRIVES e.g. 1-3 or 4,5,6 (default: all); every drive\n"
           "                          on exactly one bus             [udp:239.74.163.2:43113]\n"
           "  --lcm-url URL           LCM telemetry; must have ttl=0, '' for none\n"
           "                          [udpm://239.255.76.67:7667?ttl=0]\n"
           "  --mode lockstep|realtime                                [lockstep]\n"
           "  --duration S            trajectory length in seconds (> 0) [5]\n"
           "  --ref-hold S            hold the start pose this long first (added to the run) [0.5]\n"
           "  --rate HZ               control rate                    [1000]\n"
           "  --method NAME           %s [pd]\n"
           "  --numeric float|fixed   pm, pm-paper, gh2: float32 or int32 Q-format blocks [float]\n"
           "  --design-file FILE      pm, pm-paper, gh2: run this design (gen.synth's pm_design.txt)\n"
           "                          instead of the built-in one              [built-in]\n"
           "  --tde-cutoff HZ         tde: low-pass on the estimate   [50]\n"
           "  --usde-k S              usde-smc: filter time constant  [0.01]\n"
           "  --smc-lambda X --smc-eta X --smc-phi X --smc-ks X  usde-smc sliding mode [20 1 0.05 20]\n"
           "  --kp X --kd X           PD gains (1/s^2, 1/s)           [400, 40]\n"
           "  --torque-rate-limit X   Nm per period, all joints [each joint's limit / 10 ms]\n"
           "  --watchdog-periods N    stale periods before safe stop  [3]\n"
           "  --safe-stop zero|damping[:GAIN]                         [zero]\n"
           "  plausibility (each violation a named fault and a safe stop):\n"
           "  --checks all|none|LIST  range,velocity,step,following,torque  [all]\n"
           "  --position-margin RAD   the joint ranges widened by this    [0.1]\n"
           "  --max-velocity RAD_S    every joint                         [6.283]\n"
           "  --max-following-error RAD  every joint                      [0.5]\n"
           "  --step-tolerance RAD    position step the velocities must explain [0.01]\n"
           "  --torque-mismatch F     reported vs commanded torque, fraction of the limit [0.1]\n"
           "  --boot-timeout S        wait for the drives' heartbeats [20]\n"
           "  --lockstep-timeout S    lockstep: wall time to wait for a period's joint states [1]\n"
           "  --spin-us US            poll the bus this long before sleeping on it: a wake-up from\n"
           "                          sleep costs tens of us on a VM (lockstep speed)   [0]\n"
           "  --ref-amp A1,..,An --ref-freq F1,..,Fn  reference q_d = q0 + A (1 - cos 2 pi F t)\n"
           "                          per joint, A may be negative (both or neither) [built-in]\n"
           "  --summary FILE          write a JSON summary of the run (atomically)\n",
           method_list(" | "));
    rt_usage();
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

static int parse_double(const char *name, const char *s, double lo, double hi, double *out,
                        char *err, unsigned long errcap)
{
    char *end = NULL;
    errno = 0;
    const double v = strtod(s, &end);
    if (errno != 0 || end == s || *end != '\0' || !isfinite(v) || v < lo || v > hi) {
        snprintf(err, errcap, "%s: '%s' is not a number in [%g, %g]", name, s, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

static int copy_str(const char *name, const char *s, char *dst, size_t cap, char *err,
                    unsigned long errcap)
{
    if (strlen(s) >= cap) {
        snprintf(err, errcap, "%s: value longer than %zu characters", name, cap - 1u);
        return -1;
    }
    strcpy(dst, s);
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
    /* The multicast rule: telemetry never leaves this host (TTL exactly 0, the group on lo). */
    arm_lcm_url_t u;
    if (arm_lcm_url_parse(url, "--lcm-url", &u, err, errcap) != 0) {
        return -1;
    }
    return arm_lcm_url_check_route(&u, "--lcm-url", err, errcap);
}

int options_parse(int argc, char **argv, const arm_robot_model_t *model, options_t *opt, char *err,
                  unsigned long errcap)
{
    memset(opt, 0, sizeof(*opt));
    strcpy(opt->bus, "udp:239.74.163.2:43113");
    arm_can_bus_set_config_init(&opt->buses);
    if (arm_can_bus_set_add(&opt->buses, opt->bus, ARM_N_JOINTS, "--bus", err, errcap) != 0) {
        return -1;
    }
    int bus_given = 0;
    strcpy(opt->lcm_url, "udpm://239.255.76.67:7667?ttl=0");
    opt->mode = MODE_LOCKSTEP;
    opt->duration_s = 5.0;
    opt->rate_hz = 1000.0;
    opt->boot_timeout_s = 20.0;
    opt->lockstep_timeout_s = 1.0; /* a slow or preempted simulator is not a dead one */
    opt->ref_hold_s = 0.5;
    arm_ctl_default_config(model, &opt->ctl);
    rt_options_default(&opt->rt);
    int rate_limit_given = 0;
    int ref_amp_given = 0;
    int ref_freq_given = 0;

    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            options_usage(argv[0]);
            return 1;
        }
        if (strncmp(a, "--", 2) != 0) {
            snprintf(err, errcap, "unexpected argument '%s' (options start with --)", a);
            return -1;
        }
        if (i + 1 >= argc) {
            snprintf(err, errcap, "%s: missing value", a);
            return -1;
        }
        const char *v = argv[++i];
        double d = 0.0;
        int rc = 0;
        if (strcmp(a, "--bus") == 0) {
            if (!bus_given) {
                arm_can_bus_set_config_init(&opt->buses);
                opt->bus[0] = '\0';
                bus_given = 1;
            }
            rc = arm_can_bus_set_add(&opt->buses, v, ARM_N_JOINTS, a, err, errcap);
            if (rc == 0) {
                const size_t len = strlen(opt->bus);
                snprintf(opt->bus + len, sizeof(opt->bus) - len, "%s%s", len ? " " : "", v);
            }
        } else if (strcmp(a, "--lcm-url") == 0) {
            rc = copy_str(a, v, opt->lcm_url, sizeof(opt->lcm_url), err, errcap);
            if (rc == 0) rc = check_lcm_url(v, err, errcap);
        } else if (strcmp(a, "--summary") == 0) {
            rc = copy_str(a, v, opt->summary_path, sizeof(opt->summary_path), err, errcap);
        } else if (strcmp(a, "--mode") == 0) {
            if (strcmp(v, "lockstep") == 0) {
                opt->mode = MODE_LOCKSTEP;
            } else if (strcmp(v, "realtime") == 0) {
                opt->mode = MODE_REALTIME;
            } else {
                snprintf(err, errcap, "--mode: '%s' is not lockstep or realtime", v);
                rc = -1;
            }
        } else if (strcmp(a, "--duration") == 0) {
            rc = parse_double(a, v, 1e-3, 86400.0, &opt->duration_s, err, errcap);
        } else if (strcmp(a, "--rate") == 0) {
            rc = parse_double(a, v, 10.0, 20000.0, &opt->rate_hz, err, errcap);
        } else if (strcmp(a, "--method") == 0) {
            const arm_method_t m = arm_method_from_str(v);
            if (m == ARM_METHOD_COUNT) {
                snprintf(err, errcap, "--method: unknown method '%s' (known: %s)", v, method_list(", "));
                rc = -1;
            }
            opt->ctl.method = m;
        } else if (strcmp(a, "--numeric") == 0) {
            if (strcmp(v, "float") == 0) {
                opt->ctl.numeric = ARM_NUMERIC_FLOAT;
            } else if (strcmp(v, "fixed") == 0) {
                opt->ctl.numeric = ARM_NUMERIC_FIXED;
            } else {
                snprintf(err, errcap, "--numeric: '%s' is not float or fixed", v);
                rc = -1;
            }
        } else if (strcmp(a, "--design-file") == 0) {
            rc = design_file_load(v, &opt->design, err, errcap);
            if (rc == 0) opt->ctl.design = &opt->design.d;
        } else if (strcmp(a, "--tde-cutoff") == 0) {
            rc = parse_double(a, v, 0.1, 1e5, &d, err, errcap);
            opt->ctl.tde_cutoff_hz = (float)d;
        } else if (strcmp(a, "--usde-k") == 0) {
            rc = parse_double(a, v, 1e-5, 10.0, &d, err, errcap);
            opt->ctl.usde_k = (float)d;
        } else if (strcmp(a, "--smc-lambda") == 0) {
            rc = parse_double(a, v, 0.0, 1e4, &d, err, errcap);
            opt->ctl.smc_lambda = (float)d;
        } else if (strcmp(a, "--smc-eta") == 0) {
            rc = parse_double(a, v, 0.0, 1e5, &d, err, errcap);
            opt->ctl.smc_eta = (float)d;
        } else if (strcmp(a, "--smc-phi") == 0) {
            rc = parse_double(a, v, 1e-6, 1e3, &d, err, errcap);
            opt->ctl.smc_phi = (float)d;
        } else if (strcmp(a, "--smc-ks") == 0) {
            rc = parse_double(a, v, 0.0, 1e4, &d, err, errcap);
            opt->ctl.smc_ks = (float)d;
        } else if (strcmp(a, "--kp") == 0) {
            rc = parse_double(a, v, 0.0, 1e7, &d, err, errcap);
            opt->ctl.kp = (float)d;
        } else if (strcmp(a, "--kd") == 0) {
            rc = parse_double(a, v, 0.0, 1e5, &d, err, errcap);
            opt->ctl.kd = (float)d;
        } else if (strcmp(a, "--torque-rate-limit") == 0) {
            rc = parse_double(a, v, 1e-6, 1e6, &d, err, errcap);
            for (int j = 0; j < ARM_N_JOINTS; ++j) opt->ctl.torque_rate_limit[j] = (float)d;
            rate_limit_given = 1;
        } else if (strcmp(a, "--watchdog-periods") == 0) {
            rc = parse_double(a, v, 1.0, 1e6, &d, err, errcap);
            if (rc == 0 && d != floor(d)) {
                snprintf(err, errcap, "--watchdog-periods: '%s' is not a whole number", v);
                rc = -1;
            }
            opt->ctl.watchdog_periods = (uint32_t)d;
        } else if (strcmp(a, "--checks") == 0) {
            rc = parse_checks(v, &opt->ctl.checks, err, errcap);
        } else if (strcmp(a, "--position-margin") == 0) {
            rc = parse_double(a, v, 0.0, 10.0, &d, err, errcap);
            for (int j = 0; j < ARM_N_JOINTS; ++j) {
                const arm_link_t *l = &model->link[j];
                opt->ctl.q_min[j] = l->q_min > -ARM_UNLIMITED ? l->q_min - (float)d : -ARM_UNLIMITED;
                opt->ctl.q_max[j] = l->q_max < ARM_UNLIMITED ? l->q_max + (float)d : ARM_UNLIMITED;
            }
        } else if (strcmp(a, "--max-velocity") == 0) {
            rc = parse_double(a, v, 1e-3, 1e4, &d, err, errcap);
            for (int j = 0; j < ARM_N_JOINTS; ++j) opt->ctl.velocity_limit[j] = (float)d;
        } else if (strcmp(a, "--max-following-error") == 0) {
            rc = parse_double(a, v, 1e-6, 1e3, &d, err, errcap);
            for (int j = 0; j < ARM_N_JOINTS; ++j) opt->ctl.following_error_limit[j] = (float)d;
        } else if (strcmp(a, "--step-tolerance") == 0) {
            rc = parse_double(a, v, 1e-6, 1e3, &d, err, errcap);
            opt->ctl.step_tolerance = (float)d;
        } else if (strcmp(a, "--torque-mismatch") == 0) {
            rc = parse_double(a, v, 1e-6, 100.0, &d, err, errcap);
            for (int j = 0; j < ARM_N_JOINTS; ++j) opt->ctl.torque_mismatch_limit[j] = (float)d * model->link[j].torque_limit;
        } else if (strcmp(a, "--safe-stop") == 0) {
            if (strcmp(v, "zero") == 0) {
                opt->ctl.safe_stop_mode = ARM_SAFE_STOP_ZERO_TORQUE;
            } else if (strncmp(v, "damping", 7) == 0) {
                opt->ctl.safe_stop_mode = ARM_SAFE_STOP_DAMPING;
                opt->ctl.safe_stop_damping = 5.0f;
                if (v[7] == ':') {
                    rc = parse_double("--safe-stop damping gain", v + 8, 0.0, 1e4, &d, err, errcap);
                    opt->ctl.safe_stop_damping = (float)d;
                } else if (v[7] != '\0') {
                    snprintf(err, errcap, "--safe-stop: '%s' is not zero, damping or damping:GAIN", v);
                    rc = -1;
                }
            } else {
                snprintf(err, errcap, "--safe-stop: '%s' is not zero, damping or damping:GAIN", v);
                rc = -1;
            }
        } else if (strcmp(a, "--ref-hold") == 0) {
            rc = parse_double(a, v, 0.0, 3600.0, &opt->ref_hold_s, err, errcap);
        } else if (strcmp(a, "--ref-amp") == 0) {
            rc = parse_list(a, v, -3.2, 3.2, opt->ref_amp, err, errcap); /* the sign: which way it moves */
            ref_amp_given = 1;
        } else if (strcmp(a, "--ref-freq") == 0) {
            rc = parse_list(a, v, 0.0, 50.0, opt->ref_freq_hz, err, errcap);
            ref_freq_given = 1;
        } else if (strcmp(a, "--boot-timeout") == 0) {
            rc = parse_double(a, v, 0.01, 3600.0, &opt->boot_timeout_s, err, errcap);
        } else if (strcmp(a, "--spin-us") == 0) {
            rc = parse_double(a, v, 0.0, 1e5, &opt->spin_us, err, errcap);
        } else if (strcmp(a, "--lockstep-timeout") == 0) {
            rc = parse_double(a, v, 0.001, 3600.0, &opt->lockstep_timeout_s, err, errcap);
        } else if (rt_option_known(a)) {
            rc = rt_option_parse(a, v, &opt->rt, err, errcap);
        } else {
            snprintf(err, errcap, "unknown option '%s' (see --help)", a);
            rc = -1;
        }
        if (rc != 0) {
            return -1;
        }
    }
    if (arm_can_bus_set_check(&opt->buses, ARM_N_JOINTS, "--bus", err, errcap) != 0) {
        return -1;
    }
    if (ref_amp_given != ref_freq_given) {
        snprintf(err, errcap, "--ref-amp and --ref-freq go together (one was given without the other)");
        return -1;
    }
    opt->ref_given = ref_amp_given;
    if (opt->ctl.design == &opt->design.d && arm_pm_check_design(opt->ctl.design, (float)opt->rate_hz) != 0) {
        snprintf(err, errcap, "--design-file %s: loop_rate_hz: the design was discretised for %g Hz, this run's --rate is %g Hz",
                 opt->design.path, (double)opt->design.d.loop_rate_hz, opt->rate_hz);
        return -1;
    }
    const float default_period = opt->ctl.period_s;
    opt->ctl.period_s = (float)(1.0 / opt->rate_hz);
    if (!rate_limit_given) {
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
    return 0;
}
