/* arm_canopen_boot: configures the CiA 402 drives of one bus with the boot configurator
 * (firmware/canopen, arm/co_boot.h), prints every SDO write, each drive's units as it read them and
 * the optional objects it lacks, and the result; exits 0 when every node reached operation enabled,
 * else 1 with one line naming the node, the object and the abort code or both values (2: bad
 * arguments). The node options come from the drive configuration (gen/drives.py --boot-args).
 * docs/drives-bring-up.md. */
#define _GNU_SOURCE
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "arm/can_bus.h"
#include "arm/co_boot.h"
#include "arm/co_pdo.h"
#include "canopen_text.h"
#include "json_file.h"

static const char k_usage[] =
    "usage: arm_canopen_boot --bus SPEC --node ID[,rated=N][,encoder=INC][,gear=M/S][,torque_unit=mNm|uNm]\n"
    "         [,efficiency=E][,limit=NM][,accept_no_master_watchdog=true][,vendor=X][,product=X]...\n"
    "         [--cycle-us N] [--heartbeat-ms N] [--master-id N] [--consumer-ms N] [--sdo-timeout-ms N]\n"
    "         [--sdo-tries N] [--state-timeout-ms N] [--period-us N] [--timeout-ms N] [--json FILE]\n"
    "         [--hold-periods N] [--hold-torque NM] [--fault-reset]\n"
    "  --bus SPEC         udp | udp:GROUP:PORT | socketcan:IFACE (the drives' bus)\n"
    "  --node ...         a node to configure (repeatable): its id and the units the drive table gives, which\n"
    "                     the drive's must equal (0x6076 the motor's rated torque, in mN m or the torque_unit's,\n"
    "                     0x608F.1 increments per motor rev, 0x6091 gear; read, never written; they stand in\n"
    "                     where the drive lacks one); the gear's efficiency [1]; the joint's torque limit in N m,\n"
    "                     which the drive must give (0x6072 x 0x6076 x gear x efficiency) [not checked]; and\n"
    "                     whether a drive without a settable 0x1016.1 (master watchdog) is accepted [refused]\n"
    "  --cycle-us         0x1006 communication cycle period [1000]\n"
    "  --heartbeat-ms     0x1017 producer heartbeat of the drives [100]\n"
    "  --master-id        the master's node id (its heartbeat, 0x1016.1) [127]\n"
    "  --consumer-ms      0x1016.1 the drive's timeout for the master's heartbeat [300]\n"
    "  --sdo-timeout-ms   per SDO request [50]; --sdo-tries: tries of a transfer [3]\n"
    "  --state-timeout-ms the statusword must follow each controlword by then [500]\n"
    "  --period-us        the configurator's step period [1000]; --timeout-ms: give up after [10000]\n"
    "  --json FILE        the result as JSON: every SDO write, each node's state and identity, the fault\n"
    "  --hold-periods N   once enabled, N periods of RPDO1 (0x0F, --hold-torque) + SYNC, TPDOs decoded [0]\n"
    "  --hold-torque NM   the target torque of every node while holding, N m at the joint [0]\n"
    "  --fault-reset      a drive in fault gets one fault reset (0x6040 = 0x00, 0x80) [report the fault]\n";

static uint64_t mono_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

typedef struct {
    const char *bus;
    arm_co_boot_config_t cfg;
    uint32_t period_us;
    uint32_t timeout_ms;
    const char *json_path;
    uint32_t hold_periods;
    float hold_torque_nm;
} boot_options_t;

/* What the TPDOs of the hold phase said, per node, in SI units (arm/co_pdo.h). */
typedef struct {
    arm_co_units_t units;
    int16_t target_permille;
    uint32_t tpdo1, tpdo2;
    float q, qd, tau;
    uint16_t statusword;
} hold_state_t;

static int parse_args(int argc, char **argv, boot_options_t *o, char *err, size_t cap)
{
    arm_co_boot_default_config(&o->cfg);
    o->bus = NULL;
    o->period_us = 1000u;
    o->timeout_ms = 10000u;
    o->json_path = NULL;
    o->hold_periods = 0u;
    o->hold_torque_nm = 0.0f;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            fputs(k_usage, stdout);
            return 1;
        }
        if (strcmp(a, "--fault-reset") == 0) {
            o->cfg.fault_reset = 1u;
            continue;
        }
        if (i + 1 >= argc) {
            snprintf(err, cap, "%s: missing value (or unknown option)", a);
            return -1;
        }
        const char *v = argv[++i];
        uint32_t x = 0;
        int bad = 0;
        if (strcmp(a, "--bus") == 0) {
            o->bus = v;
        } else if (strcmp(a, "--node") == 0) {
            if (o->cfg.n_nodes >= ARM_CO_BOOT_MAX_NODES) {
                snprintf(err, cap, "--node: at most %u nodes on one bus", ARM_CO_BOOT_MAX_NODES);
                return -1;
            }
            if (canopen_parse_node(v, &o->cfg.node[o->cfg.n_nodes], err, cap) != 0) {
                return -1;
            }
            for (unsigned k = 0; k < o->cfg.n_nodes; ++k) {
                if (o->cfg.node[k].node_id == o->cfg.node[o->cfg.n_nodes].node_id) {
                    snprintf(err, cap, "--node '%s': node %u is given twice", v, o->cfg.node[k].node_id);
                    return -1;
                }
            }
            o->cfg.n_nodes++;
        } else if (strcmp(a, "--cycle-us") == 0) {
            bad = canopen_parse_u32(v, 1u, UINT32_MAX, &o->cfg.cycle_us);
        } else if (strcmp(a, "--heartbeat-ms") == 0) {
            bad = canopen_parse_u32(v, 0u, 65535u, &x);
            o->cfg.heartbeat_ms = (uint16_t)x;
        } else if (strcmp(a, "--master-id") == 0) {
            bad = canopen_parse_u32(v, 1u, 127u, &x);
            o->cfg.master_id = (uint8_t)x;
        } else if (strcmp(a, "--consumer-ms") == 0) {
            bad = canopen_parse_u32(v, 0u, 65535u, &x);
            o->cfg.consumer_ms = (uint16_t)x;
        } else if (strcmp(a, "--sdo-timeout-ms") == 0) {
            bad = canopen_parse_u32(v, 1u, 60000u, &x);
            o->cfg.sdo_timeout_us = x * 1000u;
        } else if (strcmp(a, "--sdo-tries") == 0) {
            bad = canopen_parse_u32(v, 1u, 20u, &x);
            o->cfg.sdo_tries = (uint8_t)x;
        } else if (strcmp(a, "--state-timeout-ms") == 0) {
            bad = canopen_parse_u32(v, 1u, 60000u, &x);
            o->cfg.state_timeout_us = x * 1000u;
        } else if (strcmp(a, "--period-us") == 0) {
            bad = canopen_parse_u32(v, 100u, 1000000u, &o->period_us);
        } else if (strcmp(a, "--hold-periods") == 0) {
            bad = canopen_parse_u32(v, 0u, 1000000u, &o->hold_periods);
        } else if (strcmp(a, "--hold-torque") == 0) {
            char *end = NULL;
            const double t = strtod(v, &end);
            bad = (end == v || *end != '\0' || !(t > -1e6 && t < 1e6)) ? -1 : 0;
            o->hold_torque_nm = (float)t;
        } else if (strcmp(a, "--json") == 0) {
            o->json_path = v;
        } else if (strcmp(a, "--timeout-ms") == 0) {
            bad = canopen_parse_u32(v, 1u, 3600000u, &o->timeout_ms);
        } else {
            snprintf(err, cap, "%s: unknown option (--help lists them)", a);
            return -1;
        }
        if (bad) {
            snprintf(err, cap, "%s '%s': out of range or not a number (--help)", a, v);
            return -1;
        }
    }
    if (o->bus == NULL) {
        snprintf(err, cap, "--bus: missing (udp, udp:GROUP:PORT or socketcan:IFACE)");
        return -1;
    }
    if (o->cfg.n_nodes == 0u) {
        snprintf(err, cap, "--node: missing (one per drive on the bus)");
        return -1;
    }
    if (o->json_path != NULL) { /* refused before any drive is touched, not after the boot */
        char dir[1024];
        const char *slash = strrchr(o->json_path, '/');
        const size_t n = slash == NULL ? 0u : (size_t)(slash - o->json_path);
        if (o->json_path[0] == '\0' || n >= sizeof(dir)) {
            snprintf(err, cap, "--json '%s': not a file path", o->json_path);
            return -1;
        }
        if (slash == NULL) {
            strcpy(dir, ".");
        } else if (n == 0u) {
            strcpy(dir, "/");
        } else {
            memcpy(dir, o->json_path, n);
            dir[n] = '\0';
        }
        if (access(dir, W_OK) != 0) {
            snprintf(err, cap, "--json '%s': cannot write into %s (%s)", o->json_path, dir, strerror(errno));
            return -1;
        }
    }
    return arm_can_bus_spec_valid(o->bus, err, cap) == 0 ? 0 : -1;
}

/* Once every node is enabled: n periods of RPDO1 (enable operation, the target torque in
 * per-mille of the node's rated torque) then SYNC, the TPDOs of each period decoded into SI units;
 * the master's heartbeat goes on. 0, or -1 with err set on a bus error. */
static int hold(arm_can_bus_t *bus, const boot_options_t *o, const arm_co_boot_t *boot, hold_state_t *hs, char *err,
                size_t cap)
{
    const arm_co_boot_config_t *c = &o->cfg;
    for (unsigned i = 0; i < c->n_nodes; ++i) {
        if (arm_co_boot_units(boot, i, &hs[i].units) != 0) { /* each drive's own, as the boot read them */
            snprintf(err, cap, "node %u: units cannot be built", c->node[i].node_id);
            return -1;
        }
        hs[i].target_permille = arm_co_torque_to_permille(&hs[i].units, o->hold_torque_nm);
    }
    uint64_t next = mono_us(), next_hb = next;
    for (uint32_t k = 0; k < o->hold_periods; ++k) {
        arm_can_frame_t f;
        for (unsigned i = 0; i < c->n_nodes; ++i) {
            arm_co_pack_rpdo1(c->node[i].node_id, 0x000Fu, hs[i].target_permille, &f);
            if (arm_can_bus_send(bus, &f) != ARM_BUS_OK) {
                snprintf(err, cap, "bus %s: send of RPDO1 0x%03X failed", o->bus, f.id);
                return -1;
            }
        }
        f = (arm_can_frame_t){.id = ARM_CO_COB_SYNC, .len = 0u};
        if (arm_can_bus_send(bus, &f) != ARM_BUS_OK) {
            snprintf(err, cap, "bus %s: send of SYNC failed", o->bus);
            return -1;
        }
        if (c->heartbeat_ms > 0u && mono_us() >= next_hb) {
            f = (arm_can_frame_t){.id = ARM_CO_COB_HEARTBEAT + c->master_id, .len = 1u, .data = {0x05u}};
            (void)arm_can_bus_send(bus, &f);
            next_hb += (uint64_t)c->heartbeat_ms * 1000u;
        }
        next += o->period_us;
        for (uint64_t now = mono_us(); now < next; now = mono_us()) {
            const int r = arm_can_bus_recv(bus, &f, (int)(next - now));
            if (r < 0) {
                snprintf(err, cap, "bus %s: receive failed (%d)", o->bus, r);
                return -1;
            }
            for (unsigned i = 0; r == 1 && i < c->n_nodes; ++i) {
                int32_t pos, vel;
                int16_t tq;
                uint16_t sw;
                if (arm_co_unpack_tpdo1(c->node[i].node_id, &f, &pos, &vel) == 0) {
                    hs[i].tpdo1++;
                    hs[i].q = arm_co_increments_to_rad(&hs[i].units, pos);
                    hs[i].qd = arm_co_increments_to_rad(&hs[i].units, vel);
                } else if (arm_co_unpack_tpdo2(c->node[i].node_id, &f, &tq, &sw) == 0) {
                    hs[i].tpdo2++;
                    hs[i].tau = arm_co_permille_to_torque(&hs[i].units, tq);
                    hs[i].statusword = sw;
                }
            }
        }
    }
    return 0;
}

static const char *node_state_name(arm_co_node_state_t s)
{
    return s == ARM_CO_NODE_ENABLED ? "operation_enabled" : s == ARM_CO_NODE_FAILED ? "failed" : "unfinished";
}

/* The optional objects a node lacked (or kept read-only, 0x605A and 0x605E), "0x1006 0x1016" ("" for none). */
static void absent_text(uint16_t absent, char *out, size_t cap)
{
    static const struct { uint16_t bit, index; } k_objects[] = {
        {ARM_CO_ABSENT_1006, 0x1006u}, {ARM_CO_ABSENT_1017, 0x1017u}, {ARM_CO_ABSENT_1016, 0x1016u},
        {ARM_CO_ABSENT_6502, 0x6502u}, {ARM_CO_ABSENT_6076, 0x6076u}, {ARM_CO_ABSENT_608F, 0x608Fu},
        {ARM_CO_ABSENT_6091, 0x6091u}, {ARM_CO_ABSENT_6072, 0x6072u}, {ARM_CO_ABSENT_605A, 0x605Au},
        {ARM_CO_ABSENT_605E, 0x605Eu}, {ARM_CO_ABSENT_6085, 0x6085u}};
    size_t used = 0u;
    out[0] = '\0';
    for (unsigned k = 0; k < sizeof(k_objects) / sizeof(k_objects[0]) && used + 8u < cap; ++k) {
        if (absent & k_objects[k].bit) {
            used += (size_t)snprintf(out + used, cap - used, "%s0x%04X", used ? " " : "", k_objects[k].index);
        }
    }
}

/* The result for run.json: written whole or not at all (json_file). */
static int write_json(const char *path, const arm_co_boot_t *b, const hold_state_t *hs, uint32_t hold_periods,
                      const char *result, const char *detail, char *err, size_t cap)
{
    json_file_t j;
    if (json_file_open(&j, path, "--json", err, cap) != 0) {
        return -1;
    }
    FILE *f = j.f;
    fprintf(f, "{\n  \"result\": ");
    json_string(f, result);
    fprintf(f, ",\n  \"detail\": ");
    json_string(f, detail);
    fprintf(f, ",\n  \"fault\": {\"code\": ");
    json_string(f, arm_co_fault_name(b->fault.code));
    fprintf(f, ", \"node\": %u, \"index\": %u, \"sub\": %u, \"abort_code\": %u, \"value\": %u, \"tries\": %u},\n",
            b->fault.node, b->fault.index, b->fault.sub, b->fault.abort_code, b->fault.value, b->fault.tries);
    fprintf(f, "  \"nodes\": [");
    for (unsigned i = 0; i < b->cfg.n_nodes; ++i) {
        const arm_co_node_t *n = &b->node[i];
        fprintf(f, "%s\n    {\"node\": %u, \"state\": \"%s\", \"statusword\": %u, \"identity\": [%u, %u, %u, %u]",
                i ? "," : "", b->cfg.node[i].node_id, node_state_name(n->state), n->statusword, n->identity[0],
                n->identity[1], n->identity[2], n->identity[3]);
        char absent[96];
        absent_text(n->absent, absent, sizeof(absent));
        fprintf(f, ", \"absent\": \"%s\"", absent);
        if (n->state == ARM_CO_NODE_ENABLED) {
            const arm_co_drive_units_t *u = &n->units;
            arm_co_units_t si;
            const double joint_rated = arm_co_boot_units(b, i, &si) == 0 ? si.joint_rated_torque_nm : 0.0;
            fprintf(f, ", \"units\": {\"rated_torque\": %u, \"torque_units_per_nm\": %u, \"encoder_increments\": %u, "
                       "\"encoder_revs\": %u, "
                       "\"gear\": [%u, %u], \"gear_efficiency\": %.9g, \"joint_rated_torque_nm\": %.9g, "
                       "\"max_torque_permille\": %u, \"modes\": %u, \"from_table\": %u}",
                    u->rated_torque, u->torque_units_per_nm, u->encoder_increments, u->encoder_revs, u->gear_motor_revs,
                    u->gear_shaft_revs, (double)u->gear_efficiency, joint_rated,
                    u->max_torque_permille, u->modes, u->from_table);
        }
        if (hold_periods > 0u) {
            const hold_state_t *h = &hs[i];
            fprintf(f, ", \"hold\": {\"periods\": %u, \"target_permille\": %d, \"tpdo1\": %u, \"tpdo2\": %u, "
                       "\"q_rad\": %.9g, \"qd_rad_s\": %.9g, \"tau_nm\": %.9g, \"statusword\": %u}",
                    hold_periods, h->target_permille, h->tpdo1, h->tpdo2, (double)h->q, (double)h->qd, (double)h->tau,
                    h->statusword);
        }
        fputc('}', f);
    }
    fprintf(f, "\n  ],\n  \"sdo_writes\": [");
    for (unsigned i = 0; i < b->n_log; ++i) {
        const arm_co_write_t *w = &b->log[i];
        fprintf(f, "%s\n    {\"node\": %u, \"index\": %u, \"sub\": %u, \"value\": %u, \"bytes\": %u}", i ? "," : "",
                w->node, w->index, w->sub, w->value, w->len);
    }
    fprintf(f, "\n  ]\n}\n");
    return json_file_commit(&j, "--json", err, cap);
}

int main(int argc, char **argv)
{
    static boot_options_t opt;
    static arm_can_bus_t bus;
    static arm_co_boot_t boot;
    char err[512];
    const int prc = parse_args(argc, argv, &opt, err, sizeof(err));
    if (prc == 1) {
        return 0;
    }
    if (prc != 0) {
        fprintf(stderr, "arm_canopen_boot: %s\n", err);
        return 2;
    }
    if (arm_can_bus_open(&bus, opt.bus, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_canopen_boot: %s\n", err);
        return 1;
    }
    uint64_t now = mono_us();
    const uint64_t give_up = now + (uint64_t)opt.timeout_ms * 1000u;
    if (arm_co_boot_init(&boot, &opt.cfg, now) != 0) {
        canopen_fault_text(&boot.fault, err, sizeof(err));
        fprintf(stderr, "arm_canopen_boot: %s: %s\n", arm_co_fault_name(boot.fault.code), err);
        arm_can_bus_close(&bus);
        return 2;
    }
    unsigned printed = 0;
    int rc = 1;
    uint64_t next = now;
    for (;;) {
        now = mono_us();
        rc = arm_co_boot_step(&boot, now);
        arm_can_frame_t f;
        while (arm_co_boot_take_tx(&boot, &f)) {
            if (arm_can_bus_send(&bus, &f) != ARM_BUS_OK) {
                fprintf(stderr, "arm_canopen_boot: bus %s: send of frame 0x%03X failed\n", opt.bus, f.id);
                arm_can_bus_close(&bus);
                return 1;
            }
        }
        for (; printed < boot.n_log; ++printed) {
            const arm_co_write_t *w = &boot.log[printed];
            printf("write node %u 0x%04X:%02X = 0x%0*X (%u bytes)\n", w->node, w->index, w->sub, 2 * w->len,
                   w->value, w->len);
        }
        if (rc <= 0 || now >= give_up) {
            break;
        }
        next += opt.period_us;
        /* Every frame until the next period goes to the configurator. */
        for (;;) {
            now = mono_us();
            if (now >= next) {
                break;
            }
            const int r = arm_can_bus_recv(&bus, &f, (int)(next - now));
            if (r == 1) {
                arm_co_boot_rx(&boot, &f, mono_us());
            } else if (r < 0) {
                fprintf(stderr, "arm_canopen_boot: bus %s: receive failed (%d)\n", opt.bus, r);
                arm_can_bus_close(&bus);
                return 1;
            }
        }
        if (now > next + 100u * opt.period_us) {
            next = now; /* a long stall (the host was busy): do not run the missed periods at once */
        }
    }
    static hold_state_t hs[ARM_CO_BOOT_MAX_NODES];
    const uint32_t held = rc == 0 ? opt.hold_periods : 0u;
    if (held > 0u && hold(&bus, &opt, &boot, hs, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_canopen_boot: hold: %s\n", err);
        arm_can_bus_close(&bus);
        return 1;
    }
    fflush(stdout);
    arm_can_bus_close(&bus);
    char detail[512] = "";
    const char *result = rc == 0 ? "operation_enabled" : rc < 0 ? arm_co_fault_name(boot.fault.code) : "timeout";
    if (rc < 0) {
        canopen_fault_text(&boot.fault, detail, sizeof(detail));
    } else if (rc > 0) {
        for (unsigned i = 0; i < boot.cfg.n_nodes; ++i) {
            const arm_co_node_t *n = &boot.node[i];
            if (n->state == ARM_CO_NODE_RUNNING) {
                const arm_co_action_t *a = &n->action[n->next];
                snprintf(detail, sizeof(detail), "node %u: 0x%04X:%02X still under way after %u ms",
                         boot.cfg.node[i].node_id, a->index, a->sub, opt.timeout_ms);
                break;
            }
        }
    }
    if (opt.json_path != NULL && write_json(opt.json_path, &boot, hs, held, result, detail, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_canopen_boot: %s\n", err);
        return 1;
    }
    if (rc != 0) {
        fprintf(stderr, "arm_canopen_boot: %s: %s\n", result, detail);
        return 1;
    }
    for (unsigned i = 0; i < boot.cfg.n_nodes; ++i) {
        const arm_co_node_t *n = &boot.node[i];
        printf("node %u: operation enabled (statusword 0x%04X; vendor 0x%08X product 0x%08X revision 0x%08X "
               "serial 0x%08X)\n", boot.cfg.node[i].node_id, n->statusword, n->identity[0], n->identity[1],
               n->identity[2], n->identity[3]);
        const arm_co_drive_units_t *u = &n->units;
        arm_co_units_t si;
        const double joint_rated = arm_co_boot_units(&boot, i, &si) == 0 ? si.joint_rated_torque_nm : 0.0;
        printf("node %u: units: motor rated torque %u %s%s, encoder %u/%u increments per motor revolution%s, gear "
               "%u/%u%s, efficiency %.6g, max torque %u per-mille; 1000 per-mille is %.6g N m at the joint\n",
               boot.cfg.node[i].node_id, u->rated_torque,
               u->torque_units_per_nm == 1000u ? "mN m" : u->torque_units_per_nm == 1000000u ? "uN m" : "units",
               (u->from_table & ARM_CO_EXPECT_RATED) ? " (drive table)" : "", u->encoder_increments, u->encoder_revs,
               (u->from_table & ARM_CO_EXPECT_ENCODER) ? " (drive table)" : "", u->gear_motor_revs, u->gear_shaft_revs,
               (u->from_table & ARM_CO_EXPECT_GEAR) ? " (drive table)" : "", (double)u->gear_efficiency,
               u->max_torque_permille, joint_rated);
        char absent[96];
        absent_text(n->absent, absent, sizeof(absent));
        if (absent[0] != '\0') {
            printf("node %u: optional objects it lacks (not written, or taken from the drive table): %s\n",
                   boot.cfg.node[i].node_id, absent);
        }
        if (held > 0u) {
            const hold_state_t *h = &hs[i];
            printf("node %u: held %u periods at %d per-mille: q %.6f rad, qd %.6f rad/s, tau %.3f N m, statusword "
                   "0x%04X (%u TPDO1, %u TPDO2)\n", boot.cfg.node[i].node_id, held, h->target_permille, (double)h->q,
                   (double)h->qd, (double)h->tau, h->statusword, h->tpdo1, h->tpdo2);
        }
    }
    printf("arm_canopen_boot: %u nodes operation enabled, %u SDO writes\n", boot.cfg.n_nodes, boot.n_log);
    return 0;
}
