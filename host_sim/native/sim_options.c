#include "sim_options.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/lcm_url.h"

#ifndef ARM_SIM_DEFAULT_MODEL
#define ARM_SIM_DEFAULT_MODEL "host_sim/models/ur5e_arm.xml"
#endif

static void usage(const char *prog)
{
    printf("usage: %s [options]\n"
           "The simulated arm and its emulated CiA 402 drives on the CAN bus (tools/armctl hil starts it).\n"
           "  --bus SPEC[@DRIVES]       udp | udp:GROUP:PORT | socketcan:IFACE, repeatable (up to %u\n"
           "                            buses), every drive on exactly one bus [udp, all drives]\n"
           "  --model FILE              the arm (MJCF or URDF)   [%s]\n"
           "  --keyframe NAME           start pose               [home]\n"
           "  --substeps K              MuJoCo steps per period: the period is the model's timestep\n"
           "                            times K (gen/arm.py's arm.json says which)   [1]\n"
           "  --lcm-url URL             telemetry, ttl=0; '' for none [udpm://239.255.76.67:7667?ttl=0]\n"
           "  --boot-timeout S          wait for the controller [60]\n"
           "  --idle-timeout S          silence that faults the drives [5]\n"
           "  --command-timeout-periods N  periods without a command before a drive faults [3]\n"
           "  --summary FILE            JSON summary of the run (written atomically)\n"
           "  --capture FILE            every frame on the buses, candump's log format (canplayer,\n"
           "                            python-can's LogReader, cantools decode read it)\n"
           "  --capture-clock sim|wall  its timestamps: simulated time, or the wall clock [sim]\n"
           "uncertainty (host_sim.uncertainty.UncertaintyConfig; default none):\n"
           "  --seed N --paper-ratio R --paper-knot-s S --mass-error X --inertia-error X\n"
           "  --com-error-m X --viscous B1,..,Bn --coulomb C1,..,Cn\n"
           "drives (host_sim/drive_model.py: DriveModel; default the ideal drive):\n"
           "  --encoder-bits N           counts per joint turn 2^N (1..32); position quantised\n"
           "  --position-noise-counts X  Gaussian position noise, sigma in counts (needs --encoder-bits)\n"
           "  --motor-encoder-bits N --gear-ratio R  an encoder on the motor, 2^N counts per motor\n"
           "                             turn, R motor turns per joint turn (both or neither)\n"
           "  --position-source joint|motor  the encoder the reported position comes from [joint]\n"
           "  --velocity-source joint|motor  the encoder whose differences give the velocity [joint]\n"
           "  --velocity-filter-hz F     velocity from encoder differences, first-order low-pass F\n"
           "  --torque-noise-nm X        Gaussian noise on the torque the drive reports, sigma\n"
           "  --current-loop-hz F        torque follows the command through a first-order lag of F\n"
           "  --torque-latency-us U      command arrival -> current loop input\n"
           "  --ripple R --ripple-periods P  torque ripple: x (1 + R sin(P q)) [P 6]\n"
           "bus timing (vcan and UDP have none):\n"
           "  --bus-timing off|virtual|wallclock  [off]\n"
           "  --frame-times I=ID:US,ID:US,..  worst-case length of each frame on bus I (tools/busload)\n"
           "  --bus-label I=TEXT         bus I's physical layer, for the summary\n"
           "  --controller-latency-us X  last state frame in -> commands queued [0]\n"
           "measurement:\n"
           "  --reorder-wait-us US       longest a next-period SYNC waits for this period's commands\n"
           "                             on another bus (lockstep: long; realtime: < a period) [200000]\n"
           "  --spin-us US               poll the bus this long before sleeping on it: a wake-up from\n"
           "                             sleep costs tens of us on a VM (lockstep speed)   [0]\n"
           "  --profile                  break each period's CPU time down (physics, bus, telemetry)\n"
           "  --debug-lose-bus I@PERIOD  TEST HOOK: bus I sends nothing from that period on (a lost bus)\n"
           "  --bench-mj-step N          time N bare mj_step calls on the model, print ns/step, exit\n"
           "protocol (README \"Real drives\"):\n"
           "  --protocol arm|canopen     arm: this project's frames (arm_drives.dbc); canopen: CiA 301/402\n"
           "                             slaves per firmware/protocol/cia402_servo.eds, node id = drive [arm]\n"
           "  --rated-torque-mnm N       canopen: 0x6076 motor rated torque, mN m at the joint [EDS: 150000]\n"
           "  --encoder-increments N     canopen: 0x608F.1 increments per motor turn [EDS: 524288]\n"
           "  --od-gear-ratio M:S        canopen: 0x6091 motor turns per shaft turn [EDS: 101:1]\n"
           "  --inject-overcurrent NODE:TIME  TEST HOOK (canopen): node NODE trips EMCY 0x2310 at\n"
           "                             simulated time TIME s, once operation is enabled\n",
           prog, ARM_CAN_BUS_SET_MAX, ARM_SIM_DEFAULT_MODEL);
}

static int parse_double(const char *name, const char *s, double lo, double hi, int lo_open, double *out,
                        char *err, unsigned long errcap)
{
    char *end = NULL;
    errno = 0;
    const double v = strtod(s, &end);
    if (errno != 0 || end == s || *end != '\0' || !isfinite(v) || v < lo || v > hi || (lo_open && v <= lo)) {
        snprintf(err, errcap, "%s: '%s' is not a number in %s%g, %g]", name, s, lo_open ? "(" : "[", lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

static int copy_str(const char *name, const char *s, char *dst, size_t cap, char *err, unsigned long errcap)
{
    if (strlen(s) >= cap) {
        snprintf(err, errcap, "%s: value longer than %zu characters", name, cap - 1u);
        return -1;
    }
    strcpy(dst, s);
    return 0;
}

static int parse_list(const char *name, const char *s, double *out, int *count, char *err, unsigned long errcap)
{
    const char *p = s;
    int k = 0;
    for (;;) {
        char *end = NULL;
        errno = 0;
        const double v = strtod(p, &end);
        if (errno != 0 || end == p || !isfinite(v) || v < 0.0 || v > 1e6 || k >= SIM_MAX_JOINTS ||
            (*end != ',' && *end != '\0')) {
            snprintf(err, errcap, "%s: '%s' is not a list of up to %d numbers >= 0", name, s, SIM_MAX_JOINTS);
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

int sim_options_parse(int argc, char **argv, sim_options_t *o, char *err, unsigned long errcap)
{
    memset(o, 0, sizeof(*o));
    snprintf(o->model, sizeof(o->model), "%s", ARM_SIM_DEFAULT_MODEL);
    snprintf(o->keyframe, sizeof(o->keyframe), "home");
    snprintf(o->lcm_url, sizeof(o->lcm_url), "udpm://239.255.76.67:7667?ttl=0");
    sim_uncertainty_default(&o->unc);
    sim_servo_config_default(&o->cfg.servo);
    o->cfg.lose_bus = -1;
    o->substeps = 1;
    sim_config_t *c = &o->cfg;
    c->boot_timeout_s = 60.0;
    c->idle_timeout_s = 5.0;
    c->command_timeout_periods = 3u;
    c->reorder_wait_s = 0.2;
    for (unsigned b = 0; b < ARM_CAN_BUS_SET_MAX; ++b) sim_timeline_init(&c->timelines[b]);
    unsigned frames_given = 0u;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            usage(argv[0]);
            return 1;
        }
        if (strcmp(a, "--profile") == 0) {
            c->profile = 1;
            continue;
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
            if (o->n_bus_args == ARM_CAN_BUS_SET_MAX) {
                snprintf(err, errcap, "--bus: at most %u buses", ARM_CAN_BUS_SET_MAX);
                return -1;
            }
            rc = copy_str(a, v, o->bus_args[o->n_bus_args++], ARM_CAN_BUS_SPEC_MAX, err, errcap);
        } else if (strcmp(a, "--model") == 0) {
            rc = copy_str(a, v, o->model, sizeof(o->model), err, errcap);
        } else if (strcmp(a, "--substeps") == 0) {
            rc = parse_double(a, v, 1.0, 1000.0, 0, &d, err, errcap);
            if (rc == 0 && d != floor(d)) {
                snprintf(err, errcap, "%s: '%s' is not a whole number", a, v);
                rc = -1;
            }
            o->substeps = (int)d;
        } else if (strcmp(a, "--keyframe") == 0) {
            rc = copy_str(a, v, o->keyframe, sizeof(o->keyframe), err, errcap);
        } else if (strcmp(a, "--lcm-url") == 0) {
            arm_lcm_url_t u;
            rc = copy_str(a, v, o->lcm_url, sizeof(o->lcm_url), err, errcap);
            if (rc == 0) rc = arm_lcm_url_parse(v, a, &u, err, errcap);
            if (rc == 0) rc = arm_lcm_url_check_route(&u, a, err, errcap);
        } else if (strcmp(a, "--summary") == 0) {
            rc = copy_str(a, v, o->summary, sizeof(o->summary), err, errcap);
        } else if (strcmp(a, "--capture") == 0) {
            rc = copy_str(a, v, o->capture, sizeof(o->capture), err, errcap);
        } else if (strcmp(a, "--capture-clock") == 0) {
            if (strcmp(v, "sim") != 0 && strcmp(v, "wall") != 0) {
                snprintf(err, errcap, "--capture-clock: '%s': expected sim or wall", v);
                rc = -1;
            }
            o->capture_wall = strcmp(v, "wall") == 0;
        } else if (strcmp(a, "--boot-timeout") == 0) {
            rc = parse_double(a, v, 0.0, 86400.0, 1, &c->boot_timeout_s, err, errcap);
        } else if (strcmp(a, "--idle-timeout") == 0) {
            rc = parse_double(a, v, 0.0, 86400.0, 1, &c->idle_timeout_s, err, errcap);
        } else if (strcmp(a, "--command-timeout-periods") == 0) {
            rc = parse_double(a, v, 1.0, 1e6, 0, &d, err, errcap);
            if (rc == 0 && d != floor(d)) {
                snprintf(err, errcap, "%s: '%s' is not a whole number", a, v);
                rc = -1;
            }
            c->command_timeout_periods = (uint32_t)d;
        } else if (strcmp(a, "--seed") == 0) {
            char *end = NULL;
            errno = 0;
            const unsigned long long s = strtoull(v, &end, 10);
            if (errno != 0 || end == v || *end != '\0' || v[0] == '-') {
                snprintf(err, errcap, "--seed: '%s' is not a whole number in 0..2^64-1", v);
                rc = -1;
            }
            o->unc.seed = (uint64_t)s;
        } else if (strcmp(a, "--paper-ratio") == 0) {
            rc = parse_double(a, v, 0.0, 0.999999, 0, &o->unc.paper_ratio, err, errcap);
        } else if (strcmp(a, "--paper-knot-s") == 0) {
            rc = parse_double(a, v, 1e-4, 3600.0, 0, &o->unc.paper_knot_s, err, errcap);
        } else if (strcmp(a, "--mass-error") == 0) {
            rc = parse_double(a, v, 0.0, 0.999999, 0, &o->unc.mass_error, err, errcap);
        } else if (strcmp(a, "--inertia-error") == 0) {
            rc = parse_double(a, v, 0.0, 0.999999, 0, &o->unc.inertia_error, err, errcap);
        } else if (strcmp(a, "--com-error-m") == 0) {
            rc = parse_double(a, v, 0.0, 0.999999, 0, &o->unc.com_error_m, err, errcap);
        } else if (strcmp(a, "--viscous") == 0) {
            rc = parse_list(a, v, o->unc.viscous, &o->n_viscous, err, errcap);
        } else if (strcmp(a, "--coulomb") == 0) {
            rc = parse_list(a, v, o->unc.coulomb, &o->n_coulomb, err, errcap);
        } else if (strcmp(a, "--encoder-bits") == 0) {
            rc = parse_double(a, v, 1.0, 32.0, 0, &d, err, errcap);
            if (rc == 0 && d != floor(d)) {
                snprintf(err, errcap, "%s: '%s' is not a whole number", a, v);
                rc = -1;
            }
            c->servo.encoder_bits = (int)d;
        } else if (strcmp(a, "--position-noise-counts") == 0) {
            rc = parse_double(a, v, 0.0, 1e6, 0, &c->servo.position_noise_counts, err, errcap);
        } else if (strcmp(a, "--motor-encoder-bits") == 0) {
            rc = parse_double(a, v, 1.0, 32.0, 0, &d, err, errcap);
            if (rc == 0 && d != floor(d)) {
                snprintf(err, errcap, "%s: '%s' is not a whole number", a, v);
                rc = -1;
            }
            c->servo.motor_encoder_bits = (int)d;
        } else if (strcmp(a, "--gear-ratio") == 0) {
            rc = parse_double(a, v, 1.0, 1e4, 0, &c->servo.gear_ratio, err, errcap);
        } else if (strcmp(a, "--position-source") == 0 || strcmp(a, "--velocity-source") == 0) {
            int *src = a[2] == 'p' ? &c->servo.position_source : &c->servo.velocity_source;
            if (strcmp(v, "joint") == 0) *src = SIM_ENCODER_JOINT;
            else if (strcmp(v, "motor") == 0) *src = SIM_ENCODER_MOTOR;
            else {
                snprintf(err, errcap, "%s: '%s' is not joint or motor", a, v);
                rc = -1;
            }
        } else if (strcmp(a, "--velocity-filter-hz") == 0) {
            rc = parse_double(a, v, 0.0, 1e6, 0, &c->servo.velocity_filter_hz, err, errcap);
        } else if (strcmp(a, "--torque-noise-nm") == 0) {
            rc = parse_double(a, v, 0.0, 1e4, 0, &c->servo.torque_noise_nm, err, errcap);
        } else if (strcmp(a, "--current-loop-hz") == 0) {
            rc = parse_double(a, v, 0.0, 1e7, 0, &c->servo.current_loop_hz, err, errcap);
        } else if (strcmp(a, "--torque-latency-us") == 0) {
            rc = parse_double(a, v, 0.0, 1e6, 0, &d, err, errcap);
            c->servo.latency_s = d * 1e-6;
        } else if (strcmp(a, "--ripple") == 0) {
            rc = parse_double(a, v, 0.0, 1.0, 0, &c->servo.ripple, err, errcap);
        } else if (strcmp(a, "--ripple-periods") == 0) {
            rc = parse_double(a, v, 0.0, 1e4, 0, &c->servo.ripple_periods, err, errcap);
        } else if (strcmp(a, "--bus-timing") == 0) {
            if (strcmp(v, "off") == 0) c->timing = SIM_TIMING_OFF;
            else if (strcmp(v, "virtual") == 0) c->timing = SIM_TIMING_VIRTUAL;
            else if (strcmp(v, "wallclock") == 0) c->timing = SIM_TIMING_WALLCLOCK;
            else {
                snprintf(err, errcap, "--bus-timing: '%s' is not off, virtual or wallclock", v);
                rc = -1;
            }
        } else if (strcmp(a, "--frame-times") == 0) {
            unsigned b = 0;
            const char *rest = NULL;
            rc = bus_indexed(a, v, &b, &rest, err, errcap);
            if (rc == 0 && sim_timeline_parse_frames(&c->timelines[b], rest) != 0) {
                snprintf(err, errcap, "%s: '%s' is not I=ID:US,ID:US,... (11-bit ids, 0..1e6 us)", a, v);
                rc = -1;
            }
            frames_given |= 1u << b;
        } else if (strcmp(a, "--bus-label") == 0) {
            unsigned b = 0;
            const char *rest = NULL;
            rc = bus_indexed(a, v, &b, &rest, err, errcap);
            if (rc == 0) rc = copy_str(a, rest, c->timelines[b].label, sizeof(c->timelines[b].label), err, errcap);
        } else if (strcmp(a, "--controller-latency-us") == 0) {
            rc = parse_double(a, v, 0.0, 1e6, 0, &d, err, errcap);
            c->controller_latency_s = d * 1e-6;
        } else if (strcmp(a, "--debug-lose-bus") == 0) {
            unsigned b = 0;
            unsigned long long from = 0;
            char tail = 0;
            if (sscanf(v, "%u@%llu%c", &b, &from, &tail) != 2 || b >= ARM_CAN_BUS_SET_MAX) {
                snprintf(err, errcap, "--debug-lose-bus: '%s' is not BUS@PERIOD (bus 0..%u)", v, ARM_CAN_BUS_SET_MAX - 1u);
                rc = -1;
            }
            c->lose_bus = (int)b;
            c->lose_bus_from = from;
        } else if (strcmp(a, "--reorder-wait-us") == 0) {
            rc = parse_double(a, v, 0.0, 1e7, 0, &d, err, errcap);
            c->reorder_wait_s = d * 1e-6;
        } else if (strcmp(a, "--spin-us") == 0) {
            rc = parse_double(a, v, 0.0, 1e5, 0, &c->spin_us, err, errcap);
        } else if (strcmp(a, "--protocol") == 0) {
            if (strcmp(v, "arm") == 0) o->protocol = SIM_PROTOCOL_ARM;
            else if (strcmp(v, "canopen") == 0) o->protocol = SIM_PROTOCOL_CANOPEN;
            else {
                snprintf(err, errcap, "--protocol: '%s' is not arm or canopen", v);
                rc = -1;
            }
        } else if (strcmp(a, "--rated-torque-mnm") == 0 || strcmp(a, "--encoder-increments") == 0) {
            rc = parse_double(a, v, 1.0, 4294967295.0, 0, &d, err, errcap);
            if (rc == 0 && d != floor(d)) {
                snprintf(err, errcap, "%s: '%s' is not a whole number", a, v);
                rc = -1;
            }
            *(strcmp(a, "--rated-torque-mnm") == 0 ? &o->co.preset.rated_torque_mnm
                                                   : &o->co.preset.encoder_increments) = (uint32_t)d;
            o->co_given = 1;
        } else if (strcmp(a, "--od-gear-ratio") == 0) {
            unsigned long m = 0, sh = 0;
            char tail = 0;
            if (sscanf(v, "%lu:%lu%c", &m, &sh, &tail) != 2 || m == 0u || sh == 0u || m > 0xFFFFFFFFul ||
                sh > 0xFFFFFFFFul || v[0] == '-') {
                snprintf(err, errcap, "--od-gear-ratio: '%s' is not MOTOR:SHAFT (whole numbers >= 1)", v);
                rc = -1;
            }
            o->co.preset.gear_motor = (uint32_t)m;
            o->co.preset.gear_shaft = (uint32_t)sh;
            o->co_given = 1;
        } else if (strcmp(a, "--inject-overcurrent") == 0) {
            unsigned node = 0;
            double t = 0.0;
            char tail = 0;
            if (sscanf(v, "%u:%lf%c", &node, &t, &tail) != 2 || node < 1u || node > SIM_MAX_JOINTS || !isfinite(t) ||
                t < 0.0) {
                snprintf(err, errcap, "--inject-overcurrent: '%s' is not NODE:TIME (node 1..%d, time >= 0 s)", v,
                         SIM_MAX_JOINTS);
                rc = -1;
            }
            o->co.overcurrent_node = (int)node;
            o->co.overcurrent_at_s = t;
            o->co_given = 1;
        } else if (strcmp(a, "--bench-mj-step") == 0) {
            rc = parse_double(a, v, 1.0, 1e9, 0, &d, err, errcap);
            o->bench_mj_steps = (long)d;
        } else {
            snprintf(err, errcap, "unknown option '%s' (see --help)", a);
            rc = -1;
        }
        if (rc != 0) return -1;
    }
    if (o->n_bus_args == 0u) {
        snprintf(o->bus_args[0], ARM_CAN_BUS_SPEC_MAX, "udp");
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
    if (o->co_given && o->protocol != SIM_PROTOCOL_CANOPEN) {
        snprintf(err, errcap, "--rated-torque-mnm/--encoder-increments/--od-gear-ratio/--inject-overcurrent: only with "
                 "--protocol canopen");
        return -1;
    }
    if (o->protocol == SIM_PROTOCOL_CANOPEN && c->timing != SIM_TIMING_OFF) {
        snprintf(err, errcap, "--bus-timing: not with --protocol canopen (the master's clock sets the pace)");
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

int sim_options_finish(sim_options_t *o, int n_joints, char *err, unsigned long errcap)
{
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
