#define _GNU_SOURCE
#include "controller_loop.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "arm/can_bus.h"
#include "arm/co_boot.h"
#include "arm/co_pdo.h"
#include "arm_drives.h"
#include "arm/reference.h"
#include "canopen_text.h"
#include "lateness.h"
#include "loop_port.h"
#include "task.h"

#define ALL_JOINTS ((uint32_t)((1ull << ARM_N_JOINTS) - 1u))

volatile sig_atomic_t controller_stop_signal = 0;
#define ENABLE_TIMEOUT_PERIODS 100u /* CiA 402 enable sequence: 3 periods when all is well */
#define OWED_MAX 8u /* late answers a joint may owe before a second TPDO in a period is another node's */

static int64_t now_ns(void)
{
    return port_clock_ns();
}

typedef struct {
    arm_can_bus_set_t buses;
    int bus_of[ARM_N_JOINTS]; /* index into buses of each drive's bus */
    arm_drive_bus_t drives;
    run_report_t *report;
    int64_t spin_ns;
    /* --protocol canopen: each joint's units (node j + 1), this period's TPDOs, the master's heartbeat */
    int canopen;
    arm_co_units_t units[ARM_N_JOINTS];
    uint32_t tpdo1_mask, tpdo2_mask;
    /* The answers each joint still owes (its TPDO1, its TPDO2): one more for every period its
     * answer did not come in, one fewer for every late answer read. Their answers to earlier SYNCs
     * may still arrive after this one's SYNC (a CANopen TPDO carries no SYNC counter), so a second
     * TPDO in a period is one of those late answers while the joint owes any (a plant that stalled
     * for several periods sends them in one burst), and another node on its id only once it owes
     * none. A foreign node's extra TPDOs first pay off what a lagging drive owes, so it is named at
     * most OWED_MAX periods later. */
    uint8_t tpdo1_owed[ARM_N_JOINTS], tpdo2_owed[ARM_N_JOINTS];
    int draining; /* reading what came before this period's SYNC: every TPDO then is late */
    double rx_sent_s; /* the frame being handled: when its sender sent it (-1: the transport does not say) */
    double sync_clock_s; /* the transport's clock as this period's SYNC went out (-1: it has none) */
    int64_t next_heartbeat_ns;
    lateness_t late;  /* each period's timing: which side was late when states missed the wait */
    int late_on;      /* tracking or stopping: the periods the lateness counts */
    int64_t heartbeat_ns; /* the master's heartbeat period (--heartbeat-ms; 0: none) */
    uint32_t master_id;   /* --master-id: its heartbeat's node id */
    /* TPDO2 every tpdo2_every-th SYNC (its transmission type); the joints whose TPDO2 has come */
    uint32_t tpdo2_every;
    uint32_t period;
    uint32_t tpdo2_seen;
} link_t;


/* When the sender of the frame just read from `bus` sent it, if the transport says so and the time
 * is the sender's clock at all: a python-can node that leaves its messages' timestamps at 0, or keeps
 * one Message to send again, says nothing of it (-1). */
static double sender_time(const arm_can_bus_set_t *buses, unsigned bus)
{
    const double sent = arm_can_bus_set_sent_s(buses, bus);
    if (sent < 0.0) return -1.0;
    const double age = arm_can_bus_clock_s() - sent;
    return age >= -0.001 && age <= 0.5 ? sent : -1.0;
}

/* A frame its sender sent before this period's SYNC went out (the transport says when: UDP) cannot
 * answer it, however long it took to arrive: a late answer, whatever came before it. */
static int sent_before_sync(const link_t *l)
{
    return l->rx_sent_s >= 0.0 && l->sync_clock_s >= 0.0 && l->rx_sent_s < l->sync_clock_s;
}

/* Whether joint j's TPDO (of the kind `seen` records this period) is this period's answer. One read
 * before this period's SYNC is late: counted as such, not used. A second one this period is
 * either the real answer after a late one (the joint owes answers: the late one is counted, this
 * one stands) or another node on the bus using j's id (the port stops the arm). */
static int tpdo_is_this_periods(link_t *l, uint32_t *seen, uint8_t owed[ARM_N_JOINTS], unsigned j)
{
    arm_drive_bus_t *d = &l->drives;
    const uint32_t bit = 1u << j;
    if (l->draining || sent_before_sync(l)) {
        if (owed[j] > 0u) owed[j]--;
        d->rx.wrong_counter++;
        return 0;
    }
    if ((*seen & bit) != 0u) {
        if (owed[j] > 0u) {
            owed[j]--;
            d->rx.wrong_counter++;
        } else {
            d->duplicate_mask |= bit;
        }
    }
    *seen |= bit;
    return 1;
}

/* A new period: each joint whose answer did not come in the last one owes one more (at most
 * OWED_MAX: a drive that far behind is stale long before, and the watchdog stops the arm). */
static void count_owed(uint8_t owed[ARM_N_JOINTS], uint32_t answered)
{
    for (unsigned j = 0; j < ARM_N_JOINTS; ++j) {
        if ((answered & (1u << j)) == 0u && owed[j] < OWED_MAX) owed[j]++;
    }
}

/* A CANopen drive's TPDO1 or TPDO2: its joint's state in SI units (arm/co_pdo.h); 1 if it was one.
 * The state is fresh once both came for this SYNC. */
static int canopen_rx(link_t *l, const arm_can_frame_t *f)
{
    const uint32_t base = f->id & ~0x7Fu, node = f->id & 0x7Fu;
    if ((base != ARM_CO_COB_TPDO1 && base != ARM_CO_COB_TPDO2) || node < 1u || node > ARM_N_JOINTS) {
        return 0;
    }
    const unsigned j = node - 1u;
    arm_drive_bus_t *d = &l->drives;
    int32_t pos, vel;
    int16_t tq;
    uint16_t sw;
    if (arm_co_unpack_tpdo1((uint8_t)node, f, &pos, &vel) == 0) {
        if (l->late_on) lateness_state(&l->late, now_ns(), l->rx_sent_s, l->draining ? 1u : sent_before_sync(l) ? 2u : 0u);
        if (!tpdo_is_this_periods(l, &l->tpdo1_mask, l->tpdo1_owed, j)) return 1;
        d->q[j] = arm_co_increments_to_rad(&l->units[j], pos);
        d->qd[j] = arm_co_increments_to_rad(&l->units[j], vel);
        if ((l->report->co_q_seen & (1u << j)) == 0u) { /* the units' first use, for the summary */
            l->report->co_q_seen |= 1u << j;
            l->report->co_q_first[j] = d->q[j];
        }
    } else if (arm_co_unpack_tpdo2((uint8_t)node, f, &tq, &sw) == 0) {
        if (!tpdo_is_this_periods(l, &l->tpdo2_mask, l->tpdo2_owed, j)) return 1;
        l->tpdo2_seen |= 1u << j;
        d->tau_measured[j] = arm_co_permille_to_torque(&l->units[j], tq);
        d->statusword[j] = sw;
    } else {
        d->rx.bad_length++;
        return 1;
    }
    /* TPDO2 of type n goes at every n-th SYNC after NMT start (the first SYNC is period 0): on the
     * other periods the last one's torque and statusword stand; on its own it is waited for, so
     * the state is the same however the frames interleave */
    const int tpdo2_due = (l->period + 1u) % l->tpdo2_every == 0u;
    const int tpdo2_ok = (l->tpdo2_mask & (1u << j)) != 0u || !tpdo2_due;
    if ((l->tpdo1_mask & (1u << j)) != 0u && tpdo2_ok && (d->fresh_mask & (1u << j)) == 0u) {
        d->fresh_mask |= 1u << j;
        d->rx.state++;
    }
    return 1;
}

static int send_frame(link_t *l, unsigned bus, const arm_can_frame_t *f)
{
    const int rc = arm_can_bus_set_send(&l->buses, bus, f);
    if (rc == 0) {
        l->report->frames_tx++;
    } else {
        /* A full socket buffer must not stall the period: the frame is dropped and counted;
         * the drive's own command timeout covers a lost command. */
        l->report->tx_would_block++;
    }
    return rc;
}

/* SYNC and NMT address every drive: they go on every bus. */
static void send_all(link_t *l, const arm_can_frame_t *f)
{
    for (unsigned b = 0; b < l->buses.n; ++b) {
        (void)send_frame(l, b, f);
    }
}

/* The drive a frame comes from (STATE, HEARTBEAT, EMCY), or -1 (CMD: a frame we send). */
static int sender_joint(const arm_can_frame_t *f)
{
    const int j = arm_bus_joint_of(f);
    if (j < 0 || f->id == ARM_DRIVES_DRIVE_1_CMD_FRAME_ID + (uint32_t)j) {
        return -1;
    }
    return j;
}

static void dispatch(link_t *l, const arm_can_frame_t *f, unsigned bus)
{
    l->report->frames_rx++;
    const int j = sender_joint(f);
    if (j >= 0 && l->bus_of[j] != (int)bus) {
        l->report->rx_wrong_bus++; /* drive j is not on this bus: not its frame */
        return;
    }
    l->rx_sent_s = sender_time(&l->buses, bus);
    if (!l->canopen || !canopen_rx(l, f)) {
        const arm_rx_kind_t kind = arm_bus_handle_rx(&l->drives, f); /* heartbeats and EMCY: the same in both */
        if (l->late_on && (kind == ARM_RX_STATE || kind == ARM_RX_WRONG_COUNTER)) {
            /* a state of another period: before this period's SYNC, the last period's answer; after it, the one before */
            const unsigned back = kind == ARM_RX_STATE ? 0u : l->draining ? 1u : 2u;
            lateness_state(&l->late, now_ns(), l->rx_sent_s, back);
        }
    }
}

/* Receive and dispatch frames until done() reports every joint (e.g. this period's states) or the
 * deadline passes; done == NULL: until the deadline. */
static void pump(link_t *l, int64_t deadline_ns, uint32_t (*done)(const arm_drive_bus_t *))
{
    for (;;) {
        /* A stop signal is honoured at the next period boundary: the period's states come in
         * (within the lockstep timeout at worst), so the drives' last period is a whole one. */
        if (done != NULL && done(&l->drives) == ALL_JOINTS) {
            return;
        }
        const int64_t left = deadline_ns - now_ns();
        if (left <= 0) {
            return;
        }
        arm_can_frame_t f;
        unsigned bus = 0u;
        /* Poll first, then sleep: in lockstep the answer comes within tens of microseconds,
         * sooner than a sleeping thread is woken on a VM. */
        int rc = 0;
        const int64_t spin_end = now_ns() + l->spin_ns < deadline_ns ? now_ns() + l->spin_ns : deadline_ns;
        while (rc == 0 && now_ns() < spin_end) {
            rc = arm_can_bus_set_recv(&l->buses, &f, &bus, 0);
        }
        if (rc == 0) {
            rc = arm_can_bus_set_recv(&l->buses, &f, &bus, (int)(left / 1000 + 1));
        }
        if (rc == 1) {
            dispatch(l, &f, bus);
        } else if (rc < 0) {
            return;
        }
    }
}

/* At most this many frames queued before a SYNC are read before it goes out; a flood beyond it
 * waits for the period's pump (the drives' answers are still told apart there). */
#define DRAIN_MAX (4u * ARM_N_JOINTS)

/* Before a period's SYNC: what is queued already came before it (the drives' late answers to
 * earlier SYNCs, their heartbeats and EMCY). Read now, a late answer cannot pass for this
 * period's: an arm-protocol state by its SYNC counter, a CANopen TPDO because it was read here. */
static void drain(link_t *l)
{
    l->draining = 1;
    for (unsigned i = 0; i < DRAIN_MAX; ++i) {
        arm_can_frame_t f;
        unsigned bus = 0u;
        if (arm_can_bus_set_recv(&l->buses, &f, &bus, 0) != 1) break;
        dispatch(l, &f, bus);
    }
    l->draining = 0;
}

static uint32_t states_done(const arm_drive_bus_t *b)
{
    return b->fresh_mask & ALL_JOINTS;
}

static uint32_t drives_operational(const arm_drive_bus_t *b)
{
    uint32_t m = 0u;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if ((b->heartbeat_mask & (1u << j)) != 0u && b->nmt_state[j] == ARM_NMT_STATE_OPERATIONAL) {
            m |= 1u << j;
        }
    }
    return m;
}

static void list_joints(uint32_t mask, char *out, size_t cap)
{
    size_t len = 0;
    out[0] = '\0';
    for (int j = 0; j < ARM_N_JOINTS && len + 4 < cap; ++j) {
        if ((mask & (1u << j)) != 0u) {
            len += (size_t)snprintf(out + len, cap - len, "%s%d", len > 0 ? "," : "", j + 1);
        }
    }
}

/* What a plausibility fault's value is. */
static const char *fault_quantity(arm_fault_t f)
{
    switch (f) {
    case ARM_FAULT_POSITION_RANGE: return "position, rad";
    case ARM_FAULT_VELOCITY_LIMIT: return "velocity, rad/s";
    case ARM_FAULT_POSITION_STEP: return "step, rad";
    case ARM_FAULT_FOLLOWING_ERROR: return "error, rad";
    case ARM_FAULT_TORQUE_MISMATCH: return "reported torque, Nm";
    default: return "value";
    }
}

/* HIL: a simulator that runs another arm than this controller was built for is refused at boot
 * (the simulator announces its model with SIM_IDENTITY; real drives never do). */
static int sim_identity_mismatch(const link_t *l, const arm_robot_model_t *model)
{
    return l->drives.sim_identity_seen &&
           (l->drives.sim_model_hash32 != (uint32_t)model->model_hash || l->drives.sim_n_joints != ARM_N_JOINTS);
}

static int boot(link_t *l, const options_t *opt, const arm_robot_model_t *model, telemetry_t *telem)
{
    const int64_t start = now_ns();
    const int64_t give_up = start + (int64_t)(opt->boot_timeout_s * 1e9);
    arm_can_frame_t nmt;
    arm_bus_make_nmt(ARM_NMT_START, 0u, &nmt);
    /* NMT start is repeated because the drives may join the bus after us. */
    while (now_ns() < give_up && controller_stop_signal == 0) {
        send_all(l, &nmt);
        int64_t slice = now_ns() + 50000000LL;
        if (slice > give_up) slice = give_up;
        pump(l, slice, drives_operational);
        if (sim_identity_mismatch(l, model)) {
            snprintf(l->report->reason, sizeof(l->report->reason),
                     "boot: the simulator runs another arm (model hash %08x, %u joints) than this controller was "
                     "built for (%08x, %d joints): build the controller for the simulator's model, or start the "
                     "simulator with this controller's (tools/armctl does both from one --model/--arm)",
                     (unsigned)l->drives.sim_model_hash32, (unsigned)l->drives.sim_n_joints,
                     (unsigned)(uint32_t)model->model_hash, ARM_N_JOINTS);
            return -1;
        }
        if (drives_operational(&l->drives) == ALL_JOINTS) {
            l->report->boot_s = (double)(now_ns() - start) * 1e-9;
            telemetry_event(telem, 0, "info", "all drives operational");
            return 0;
        }
    }
    char missing[64];
    list_joints(ALL_JOINTS & ~drives_operational(&l->drives), missing, sizeof(missing));
    snprintf(l->report->reason, sizeof(l->report->reason),
             "boot: drive(s) %s not operational within %.1f s (no heartbeat with NMT state "
             "operational; is the simulator on bus '%.200s'?)",
             missing, opt->boot_timeout_s, opt->bus);
    return -1;
}

/* --protocol canopen: the CANopen master boots every bus's drives side by side (arm/co_boot.h),
 * to operation enabled in CST with zero torque. Node = drive number, or the drive table's (--node);
 * each joint's units are its drive's, read at boot (and checked against the drive table's). */
static arm_co_boot_t co[ARM_CAN_BUS_SET_MAX];

static int boot_canopen_run(link_t *l, const options_t *opt, const arm_robot_model_t *model, telemetry_t *telem);

/* The boot, and its record for the summary (run.json): each bus's SDO writes, the first fault. */
static int boot_canopen(link_t *l, const options_t *opt, const arm_robot_model_t *model, telemetry_t *telem)
{
    memset(co, 0, sizeof(co));
    const int64_t start = now_ns();
    const int rc = boot_canopen_run(l, opt, model, telem);
    run_report_t *r = l->report;
    r->canopen = 1;
    r->co_boot_s = (double)(now_ns() - start) * 1e-9;
    for (unsigned b = 0; b < l->buses.n; ++b) {
        for (unsigned i = 0; i < co[b].n_log && r->n_co_writes < ARM_REPORT_CO_WRITES_MAX; ++i) {
            r->co_writes[r->n_co_writes++] = co[b].log[i];
        }
        if (r->co_fault.code == ARM_CO_FAULT_NONE) r->co_fault = co[b].fault;
    }
    return rc;
}

/* "joint 3: " for the joint whose drive a boot fault about the joint names (bus b: its torque limit,
 * its watchdog on the master), "" otherwise. */
static void fault_joint_text(const link_t *l, unsigned b, const arm_co_fault_t *f, char *out, size_t cap)
{
    out[0] = '\0';
    if (f->code != ARM_CO_FAULT_TORQUE_LIMIT && f->code != ARM_CO_FAULT_NO_WATCHDOG) return;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const arm_co_boot_t *cb = &co[b];
        for (unsigned i = 0; l->bus_of[j] == (int)b && i < cb->cfg.n_nodes; ++i) {
            if (cb->cfg.node[i].node_id == f->node && f->node != 0u) {
                snprintf(out, cap, "joint %d: ", j + 1);
            }
        }
        if (out[0] != '\0') return;
    }
}

static int boot_canopen_run(link_t *l, const options_t *opt, const arm_robot_model_t *model, telemetry_t *telem)
{
    unsigned co_slot[ARM_N_JOINTS] = {0}; /* joint j is node co_slot[j] of its bus's boot */
    const int64_t start = now_ns();
    const int64_t give_up = start + (int64_t)(opt->boot_timeout_s * 1e9);
    for (unsigned b = 0; b < l->buses.n; ++b) {
        arm_co_boot_config_t cfg;
        arm_co_boot_default_config(&cfg);
        cfg.cycle_us = (uint32_t)(1e6 / opt->rate_hz + 0.5);
        cfg.heartbeat_ms = (uint16_t)opt->co_heartbeat_ms;
        cfg.master_id = (uint8_t)opt->co_master_id;
        cfg.consumer_ms = (uint16_t)opt->co_consumer_ms;
#ifdef CANOPEN_CONSUMER_MIN_MS /* the MCU image's floor (its CMake): its clock is QEMU's virtual time */
        if (cfg.consumer_ms != 0u && cfg.consumer_ms < CANOPEN_CONSUMER_MIN_MS) cfg.consumer_ms = CANOPEN_CONSUMER_MIN_MS;
#endif
        /* drives that come up after the controller (a slower process, a bus powered later) are
         * waited for, as the arm protocol waits for their heartbeats: for the first half of the
         * boot timeout, so that one that never comes is still named (no_answer, node, 0x1000) */
        const double presence_s = 0.5 * opt->boot_timeout_s;
        cfg.presence_timeout_us = (uint32_t)(presence_s < 4000.0 ? presence_s * 1e6 : 4e9);
        cfg.rpdo1.trans = opt->rpdo_type;
        cfg.tpdo2.trans = opt->tpdo2_type;
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            if (l->bus_of[j] != (int)b || cfg.n_nodes >= ARM_CO_BOOT_MAX_NODES) continue;
            co_slot[j] = cfg.n_nodes;
            arm_co_node_config_t *nc = &cfg.node[cfg.n_nodes++];
            /* the arm's drive table (gen/drives.py), else the drive number and the drive's own units */
            *nc = opt->n_nodes == ARM_N_JOINTS ? opt->node[j] : (arm_co_node_config_t){.node_id = (uint8_t)(j + 1)};
            /* the controller's own torque limit: a drive that cannot give it at the joint is refused */
            nc->joint_torque_limit_nm = model->link[j].torque_limit;
        }
        if (arm_co_boot_init(&co[b], &cfg, (uint64_t)(now_ns() / 1000)) != 0) {
            char text[400], joint[24];
            canopen_fault_text(&co[b].fault, text, sizeof(text));
            fault_joint_text(l, b, &co[b].fault, joint, sizeof(joint));
            snprintf(l->report->reason, sizeof(l->report->reason), "boot: canopen: bus %u: %s%s", b, joint, text);
            return -1;
        }
    }
    int rc[ARM_CAN_BUS_SET_MAX];
    for (unsigned b = 0; b < l->buses.n; ++b) rc[b] = 1;
    while (now_ns() < give_up && controller_stop_signal == 0) {
        int running = 0;
        for (unsigned b = 0; b < l->buses.n; ++b) {
            if (rc[b] == 1) rc[b] = arm_co_boot_step(&co[b], (uint64_t)(now_ns() / 1000));
            arm_can_frame_t f;
            while (arm_co_boot_take_tx(&co[b], &f)) (void)send_frame(l, b, &f);
            if (rc[b] < 0) {
                char text[400], joint[24];
                canopen_fault_text(&co[b].fault, text, sizeof(text));
                fault_joint_text(l, b, &co[b].fault, joint, sizeof(joint));
                snprintf(l->report->reason, sizeof(l->report->reason), "boot: canopen: %s: %s%s",
                         arm_co_fault_name(co[b].fault.code), joint, text);
                return -1;
            }
            running |= rc[b] == 1;
        }
        if (!running) {
            for (int j = 0; j < ARM_N_JOINTS; ++j) { /* each joint's units: its drive's, as the boot read them */
                const arm_co_boot_t *cb = &co[l->bus_of[j]];
                l->report->co_units[j] = cb->node[co_slot[j]].units;
                if (arm_co_boot_units(cb, co_slot[j], &l->units[j]) != 0) {
                    snprintf(l->report->reason, sizeof(l->report->reason),
                             "boot: canopen: node %u: its units (rated torque, encoder, gear) cannot be built",
                             cb->cfg.node[co_slot[j]].node_id);
                    return -1;
                }
            }
            unsigned writes = 0u;
            for (unsigned b = 0; b < l->buses.n; ++b) writes += co[b].n_log;
            l->report->boot_s = (double)(now_ns() - start) * 1e-9;
            char text[120];
            snprintf(text, sizeof(text), "all drives operation enabled (CANopen boot, %u SDO writes)", writes);
            telemetry_event(telem, 0, "info", text);
            return 0;
        }
        const int64_t slice_end = now_ns() + 1000000LL; /* the configurator's period: 1 ms */
        for (int64_t t = now_ns(); t < slice_end; t = now_ns()) {
            arm_can_frame_t f;
            unsigned bus = 0u;
            const int r = arm_can_bus_set_recv(&l->buses, &f, &bus, (int)((slice_end - t) / 1000 + 1));
            if (r == 1 && bus < l->buses.n) {
                l->report->frames_rx++;
                arm_co_boot_rx(&co[bus], &f, (uint64_t)(now_ns() / 1000));
            } else if (r < 0) {
                break;
            }
        }
    }
    snprintf(l->report->reason, sizeof(l->report->reason), "boot: canopen: %s within %.1f s",
             controller_stop_signal != 0 ? "stopped by a signal" : "drives not operation enabled", opt->boot_timeout_s);
    return -1;
}

/* Each bus's commands in one batch (one syscall on the UDP transport): the period's critical
 * path in lockstep is mostly syscalls. Every drive gets controlword cw. */
static void send_commands(link_t *l, const arm_ctl_output_t *out, uint16_t cw)
{
    arm_can_frame_t batch[ARM_CAN_BUS_SET_MAX][ARM_N_JOINTS];
    unsigned count[ARM_CAN_BUS_SET_MAX] = {0};
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const unsigned b = (unsigned)l->bus_of[j];
        if (l->canopen) {
            arm_co_pack_rpdo1((uint8_t)(j + 1), cw, arm_co_torque_to_permille(&l->units[j], out->tau[j]),
                              &batch[b][count[b]++]);
        } else {
            arm_bus_make_cmd(&l->drives, j, cw, out->tau[j], &batch[b][count[b]++]);
        }
    }
    for (unsigned b = 0; b < l->buses.n; ++b) {
        if (count[b] == 0u) continue;
        const unsigned sent = arm_can_bus_set_send_many(&l->buses, b, batch[b], count[b]);
        l->report->frames_tx += sent;
        l->report->tx_would_block += count[b] - sent; /* dropped and counted, as send_frame does */
    }
}

/* Everything the periodic loop carries from one period to the next. */
typedef struct {
    const options_t *opt;
    telemetry_t *telem;
    run_report_t *report;
    arm_ctl_t ctl;
    task_t task; /* what the arm does: the reference source (task.h) */
    int task_over; /* 1: the task ended (the arm is stopped next period); -1: it stopped the arm (a fault) */
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    arm_state_t last_state;
    int64_t next_deadline; /* realtime: the next period's start */
    int64_t period_ns;
    uint32_t k_run;        /* tracking periods done */
    uint32_t k_published;  /* periods in telemetry: the tracking ones, then the stop's */
    int states_missing;    /* lockstep: a period's states did not come within the wait (supervise) */
} loop_t;

/* Periods on the clock: realtime, and lockstep too where the port paces it (the MCU's SysTick-driven
 * SYNC: its states are still waited for, but the next SYNC goes no sooner than its time). */
static int paced(const loop_t *p)
{
    /* a planner's stream comes on the wall clock: a lockstep rehearsal of it keeps that time too */
    return p->opt->mode == MODE_REALTIME || port_paces_lockstep || p->opt->task == TASK_STREAM;
}

/* Enable: the CiA 402 sequence with zero torque, one step a period. 1 when every drive is
 * operation enabled (tracking starts), 0 while enabling, -1 on a boot failure (reason set). */
static int enable(link_t *l, loop_t *p, uint32_t k, uint32_t fresh)
{
    uint32_t enabled = 0u;
    for (int j = 0; j < ARM_N_JOINTS && !l->canopen; ++j) {
        const uint16_t sw = l->drives.statusword[j];
        if ((fresh & (1u << j)) != 0u && arm_sw_operation_enabled(sw)) {
            enabled |= 1u << j;
        }
        arm_can_frame_t f;
        arm_bus_make_cmd(&l->drives, j, arm_cia402_enable_controlword(sw), 0.0f, &f);
        send_frame(l, (unsigned)l->bus_of[j], &f);
    }
    for (int j = 0; j < ARM_N_JOINTS && l->canopen; ++j) { /* enabled, zero torque until tracking */
        arm_can_frame_t f;
        arm_co_pack_rpdo1((uint8_t)(j + 1), ARM_CW_ENABLE_OPERATION, 0, &f);
        send_frame(l, (unsigned)l->bus_of[j], &f);
    }
    if (l->canopen) { /* the boot enabled them: tracking starts with the first whole state */
        enabled = fresh & l->tpdo2_seen;
    }
    if (enabled == ALL_JOINTS) {
        char err[200];
        if (task_begin(&p->task, p->opt, l->drives.q, p->telem, &p->report->task, p->k_run, err, sizeof(err)) != 0) {
            snprintf(p->report->reason, sizeof(p->report->reason), "%s", err);
            p->report->result = RUN_FAULT;
            telemetry_event(p->telem, 0, "fault", p->report->reason);
            return -1;
        }
        telemetry_event(p->telem, 0, "info", "all drives operation enabled; tracking starts");
        return 1;
    }
    if (l->drives.rx.foreign_master != 0u) {
        snprintf(p->report->reason, sizeof(p->report->reason),
                 "boot: another master on the bus (%u SYNC or command frame(s) this controller did not send)",
                 l->drives.rx.foreign_master);
    } else if (k >= ENABLE_TIMEOUT_PERIODS) {
        char missing[64];
        list_joints(ALL_JOINTS & ~enabled, missing, sizeof(missing));
        const int j0 = __builtin_ctz(ALL_JOINTS & ~enabled);
        snprintf(p->report->reason, sizeof(p->report->reason),
                 "boot: drive(s) %s not operation enabled after %u periods (drive %d statusword 0x%04x%s)",
                 missing, ENABLE_TIMEOUT_PERIODS, j0 + 1, l->drives.statusword[j0],
                 (fresh & (1u << j0)) ? "" : ", no state received");
    } else {
        return 0;
    }
    p->report->result = RUN_BOOT_FAILED;
    telemetry_event(p->telem, 0, "fault", p->report->reason);
    return -1;
}

/* Supervise: what the drives' frames of this period say (the core's bus master checks them); a
 * problem is a named fault and a safe stop. */
static void supervise(link_t *l, loop_t *p)
{
    if (p->ctl.state == ARM_STATE_SAFE_STOP) return;
    const uint32_t fresh = l->drives.fresh_mask & ALL_JOINTS;
    const arm_bus_fault_t f = arm_bus_supervise(&l->drives, p->opt->mode == MODE_LOCKSTEP,
                                                p->ctl.state == ARM_STATE_RUNNING);
    char *reason = p->report->reason;
    const size_t cap = sizeof(p->report->reason);
    char missing[64];
    switch (f.condition) {
    case ARM_BUS_WELL: return;
    case ARM_BUS_STATES_MISSING:
        p->states_missing = 1;
        list_joints(ALL_JOINTS & ~fresh, missing, sizeof(missing));
        snprintf(reason, cap, "period %u: no joint state from drive(s) %s within %.3f s (simulator stopped?)",
                 p->k_run, missing, p->opt->lockstep_timeout_s);
        break;
    case ARM_BUS_DRIVE_EMCY:
        snprintf(reason, cap, "period %u: drive %d reports a fault (EMCY 0x%04x)", p->k_run, f.joint + 1,
                 (unsigned)f.value);
        break;
    case ARM_BUS_DUPLICATE_STATE:
        snprintf(reason, cap, "period %u: drive %d's state came twice for one SYNC: another node uses its id",
                 p->k_run, f.joint + 1);
        break;
    case ARM_BUS_FOREIGN_MASTER:
        snprintf(reason, cap, "period %u: another master on the bus: %u SYNC or command frame(s) this controller "
                 "did not send", p->k_run, (unsigned)f.value);
        break;
    case ARM_BUS_LEFT_ENABLED:
        snprintf(reason, cap, "period %u: drive %d left operation enabled (statusword 0x%04x, error %u)", p->k_run,
                 f.joint + 1, (unsigned)f.value, l->drives.drive_error[f.joint]);
        break;
    }
    arm_ctl_external_fault(&p->ctl);
}

/* Control: the core's step on this period's joint states and reference, and the commands out.
 * Returns the step's own compute time. */
static int64_t control(link_t *l, loop_t *p)
{
    memcpy(p->in.q, l->drives.q, sizeof(p->in.q));
    memcpy(p->in.qd, l->drives.qd, sizeof(p->in.qd));
    p->in.fresh_mask = l->drives.fresh_mask & ALL_JOINTS;
    memcpy(p->in.tau_measured, l->drives.tau_measured, sizeof(p->in.tau_measured));
    char err[240];
    const int over = task_step(&p->task, (float)p->k_run * p->opt->ctl.period_s, p->k_run, p->in.q, p->out.tau, &p->in,
                               err, sizeof(err));
    if (over < 0 && p->task_over == 0) { /* the task stopped the arm (commissioning's bound): a fault */
        snprintf(p->report->reason, sizeof(p->report->reason), "period %u: %s", p->k_run, err);
        telemetry_event(p->telem, p->k_run, "fault", p->report->reason);
        p->report->result = RUN_FAULT;
    }
    if (over != 0 && p->task_over == 0) p->task_over = over;
    const int64_t c0 = now_ns();
    port_control_step(&p->ctl, &p->in, &p->out);
    if (p->opt->rt.debug_slow_step_us > 0u) {
        rt_debug_busy_wait_us(p->opt->rt.debug_slow_step_us); /* TEST HOOK: forces overruns */
    }
    const int64_t compute = now_ns() - c0;
    if (p->out.state == ARM_STATE_RUNNING && p->task_over == 0) task_track(&p->task, p->out.e);
    /* a stop begins in the very period of its fault: the drives quick-stop under the hold */
    const int stopping = p->out.state == ARM_STATE_FAULT || p->out.state == ARM_STATE_SAFE_STOP;
    send_commands(l, &p->out, stopping ? ARM_CW_QUICK_STOP : ARM_CW_ENABLE_OPERATION);
    return compute;
}

/* Publish: the period's telemetry, its timing, state changes and a fault's reason. 0 to go on, -1
 * when the controller stopped the arm. */
/* The period's ARM_CTL and ARM_TIMING (one each per period, numbered on: the tracking periods,
 * then a stop's), and the next deadline. */
static void publish_period(loop_t *p, uint32_t k, int64_t wake_latency, int64_t compute, int64_t cycle)
{
    run_report_t *report = p->report;
    const uint32_t step = p->k_published++;
    telem_controller_t snap = {.step = step, .bus_period = k, .t = (double)step * p->opt->ctl.period_s,
                               .method = (int8_t)p->opt->ctl.method, .out = p->out};
    memcpy(snap.q, p->in.q, sizeof(snap.q));
    memcpy(snap.qd, p->in.qd, sizeof(snap.qd));
    memcpy(snap.q_d, p->in.q_d, sizeof(snap.q_d));
    telemetry_controller(p->telem, &snap);
    if (paced(p)) {
        p->next_deadline += p->period_ns;
        if (now_ns() > p->next_deadline) {
            report->overruns++;
            /* Skip the missed deadlines instead of bursting to catch up. */
            while (p->next_deadline < now_ns()) p->next_deadline += p->period_ns;
        }
    }
    const telem_timing_t tm = {.step = step, .period_ns = (int32_t)p->period_ns,
                               .wake_latency_ns = (int32_t)wake_latency, .compute_ns = (int32_t)compute,
                               .cycle_ns = (int32_t)cycle, .overruns = (int64_t)report->overruns};
    telemetry_timing(p->telem, &tm);
}

static int publish(loop_t *p, uint32_t k, int64_t wake_latency, int64_t compute, int64_t cycle)
{
    run_report_t *report = p->report;
    publish_period(p, k, wake_latency, compute, cycle);
    report->steps_done = ++p->k_run;
    const arm_ctl_output_t *out = &p->out;
    if (out->state != p->last_state) {
        char text[160];
        snprintf(text, sizeof(text), "state %s -> %s (fault: %s)", arm_state_str(p->last_state),
                 arm_state_str(out->state), arm_fault_str(out->fault));
        telemetry_event(p->telem, p->k_run, out->state == ARM_STATE_FAULT ? "fault" : "info", text);
        p->last_state = out->state;
    }
    if (out->state != ARM_STATE_FAULT && out->state != ARM_STATE_SAFE_STOP) {
        return 0;
    }
    if (report->reason[0] == '\0' && out->fault_joint >= 0) {
        snprintf(report->reason, sizeof(report->reason), "period %u: %s: joint %d (%s %.6g)", p->k_run,
                 arm_fault_str(out->fault), out->fault_joint + 1, fault_quantity(out->fault),
                 (double)out->fault_value);
    } else if (report->reason[0] == '\0') {
        snprintf(report->reason, sizeof(report->reason), "period %u: %s", p->k_run, arm_fault_str(out->fault));
    }
    telemetry_event(p->telem, p->k_run, "fault", report->reason);
    report->result = RUN_FAULT;
    return -1;
}

/* Bus period k begins: what came before its SYNC is read, then the SYNC goes out. now: the bus's
 * time, which paces the master's heartbeat: the wall clock in realtime; in lockstep the periods
 * themselves (period_time), so a run sends the same frames however loaded the machine is. */
static void start_period(link_t *l, uint32_t k, int64_t now)
{
    arm_can_frame_t sync;
    arm_bus_begin_period(&l->drives, k, &sync);
    if (l->canopen) {
        sync.len = 0u; /* CiA 301 SYNC without a counter (0x1019 = 0) */
        const int tpdo2_was_due = k > 0u && k % l->tpdo2_every == 0u;
        if (k == 0u) {
            memset(l->tpdo1_owed, 0, sizeof(l->tpdo1_owed));
            memset(l->tpdo2_owed, 0, sizeof(l->tpdo2_owed));
        } else {
            count_owed(l->tpdo1_owed, l->tpdo1_mask);
            /* a TPDO2 late for its period may come a period after that one too (a non-due one between) */
            if (tpdo2_was_due) count_owed(l->tpdo2_owed, l->tpdo2_mask);
        }
        l->tpdo1_mask = l->tpdo2_mask = 0u;
        l->period = k;
        if (l->heartbeat_ns > 0 && now >= l->next_heartbeat_ns) { /* the drives consume it (0x1016.1) */
            const arm_can_frame_t hb = {.id = ARM_CO_COB_HEARTBEAT + l->master_id, .len = 1u, .data = {0x05u}};
            send_all(l, &hb);
            l->next_heartbeat_ns = now + l->heartbeat_ns;
        }
    }
    drain(l);
    l->sync_clock_s = arm_can_bus_clock_s();
    send_all(l, &sync);
    l->report->bus_periods = k + 1u;
}

/* The frames the kernel dropped on a full receive queue, on every bus so far. */
static uint64_t rx_dropped(const link_t *l)
{
    uint64_t n = 0u;
    for (unsigned b = 0; b < l->buses.n; ++b) n += arm_can_bus_rx_kernel_drops(&l->buses.bus[b]);
    return n;
}

/* The period's SYNC is out (start_period): its timing begins, waiting for the states until wait_until. */
static void begin_timing(link_t *l, uint32_t k, int64_t wake_latency, int64_t wait_until)
{
    const int64_t t = now_ns();
    l->late_on = 1;
    lateness_begin(&l->late, k, wake_latency, t, l->sync_clock_s, wait_until - t, l->report->tx_would_block,
                   rx_dropped(l));
}

/* The bus's time at the start of period k (start_period). */
static int64_t period_time(const loop_t *p, uint32_t k, int64_t wall)
{
    return p->opt->mode == MODE_REALTIME ? wall : (int64_t)k * p->period_ns;
}

/* Sleep to the period's absolute deadline (paced); the wake-up's lateness. */
static int64_t wait_for_period(loop_t *p)
{
    if (!paced(p)) return 0;
    port_clock_sleep_until(p->next_deadline);
    return now_ns() - p->next_deadline;
}

/* ---- the controlled stop ------------------------------------------------------------------- */
#define DISABLE_PERIODS_MAX 200u /* after the quick stop: disable voltage until the drives show it */

/* A drive whose quick stop is done: switch on disabled (its brake closed, its power stage off), or
 * in fault (its own fault reaction done). */
static int drive_stopped(uint16_t sw)
{
    return (sw & 0x004Fu) == 0x0040u || (sw & 0x004Fu) == 0x0008u;
}

static uint32_t stopped_drives(const link_t *l)
{
    uint32_t m = 0u;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if (drive_stopped(l->drives.statusword[j])) m |= 1u << j;
    }
    return m;
}

/* One period of a stop: SYNC, the drives' states (not waited for once the plant fell silent in
 * lockstep, where a wait costs the lockstep timeout), the core's hold, the commands with controlword
 * cw, the period's telemetry. The states that came. */
static uint32_t stop_period(link_t *l, loop_t *p, uint32_t k, uint16_t cw, int wait)
{
    const options_t *opt = p->opt;
    const int64_t wake_latency = wait_for_period(p);
    const int64_t cycle_start = now_ns();
    start_period(l, k, period_time(p, k, cycle_start));
    const int64_t wait_until = !wait ? cycle_start
                               : opt->mode == MODE_REALTIME ? p->next_deadline + p->period_ns * 8 / 10
                                                            : cycle_start + (int64_t)(opt->lockstep_timeout_s * 1e9);
    begin_timing(l, k, wake_latency, wait_until);
    pump(l, wait_until, states_done);
    const uint32_t fresh = l->drives.fresh_mask & ALL_JOINTS;
    lateness_missing(&l->late, ALL_JOINTS & ~fresh);
    memcpy(p->in.q, l->drives.q, sizeof(p->in.q));
    memcpy(p->in.qd, l->drives.qd, sizeof(p->in.qd));
    p->in.fresh_mask = fresh;
    memcpy(p->in.tau_measured, l->drives.tau_measured, sizeof(p->in.tau_measured));
    const int64_t c0 = now_ns();
    port_control_step(&p->ctl, &p->in, &p->out);
    const int64_t compute = now_ns() - c0;
    send_commands(l, &p->out, cw);
    publish_period(p, k, wake_latency, compute, now_ns() - cycle_start);
    return fresh;
}

/* A stop for lateness (the watchdog, a lockstep wait that ran out) says which side was late and by
 * how much, from the periods that led to it: in its reason, in ARM_EVENT and in the summary. */
static void explain_late_stop(link_t *l, loop_t *p)
{
    run_report_t *r = p->report;
    const int watchdog = p->out.fault == ARM_FAULT_STALE_INPUT || r->final_fault == ARM_FAULT_STALE_INPUT;
    if (!watchdog && !p->states_missing) return;
    const uint32_t periods = p->states_missing ? 1u : p->ctl.cfg.watchdog_periods + 1u;
    char text[300];
    r->late_side = lateness_explain(&l->late, 1u, periods, r->tx_would_block, rx_dropped(l), text, sizeof(text));
    snprintf(r->late_text, sizeof(r->late_text), "%s", text);
    const size_t len = strlen(r->reason);
    snprintf(r->reason + len, sizeof(r->reason) - len, "; %s", text);
    telemetry_event(p->telem, p->k_published, "fault", text);
}

/* The one way this controller stops the arm, whatever asked (a fault, a stop signal, the end of the
 * run): from period k on, every drive is told to quick-stop (controlword 0x0002: its 0x605A ramp to
 * standstill, then its brake closes with the power stage on, then switch on disabled) while the
 * core holds the arm (gravity compensation and damping, --safe-stop) as the drives' target torque;
 * once every drive reports switch on disabled or fault (or after --stop-timeout, or once the plant
 * has been silent for the watchdog's periods) every drive is disabled (0x0000), then stopped (NMT).
 * Telemetry (ARM_EVENT) says which safe state the arm reached; the report keeps it. Returns the
 * next bus period. */
static uint32_t controlled_stop(link_t *l, loop_t *p, uint32_t k, run_stop_cause_t cause)
{
    const options_t *opt = p->opt;
    run_stop_t *st = &p->report->stop;
    st->cause = cause;
    st->from_bus_period = k;
    arm_ctl_stop(&p->ctl);
    telemetry_event(p->telem, p->k_published, "info",
                    "safe stop: drives quick-stopping (controlword 0x0002) under the hold (gravity compensation and "
                    "damping); their brakes close once they stand still");
    const uint32_t limit = (uint32_t)(opt->stop_timeout_s * opt->rate_hz + 0.5);
    uint32_t silent = 0u, periods = 0u;
    int wait = 1;
    while (periods < limit && stopped_drives(l) != ALL_JOINTS && silent <= p->ctl.cfg.watchdog_periods) {
        const uint32_t fresh = stop_period(l, p, k++, ARM_CW_QUICK_STOP, wait);
        periods++;
        silent = fresh == 0u ? silent + 1u : 0u;
        if (fresh != ALL_JOINTS && opt->mode == MODE_LOCKSTEP) wait = 0; /* the plant fell silent: no more waits */
        if (periods == 1u) explain_late_stop(l, p); /* what came late for the stop's periods has been read */
    }
    st->quick_stop_periods = periods;
    st->stopped_mask = stopped_drives(l);
    char missing[64], text[300];
    list_joints(ALL_JOINTS & ~st->stopped_mask, missing, sizeof(missing));
    if (st->stopped_mask == ALL_JOINTS) {
        st->braked = 1;
        snprintf(text, sizeof(text), "safe stop: arm braked: every drive reports switch on disabled or fault (its ramp "
                 "done, its brake closed, its power stage off) after %u periods", periods);
    } else if (silent > p->ctl.cfg.watchdog_periods) {
        snprintf(text, sizeof(text), "safe stop: brakes not confirmed: no joint state for %u periods (drive(s) %s not "
                 "seen switch on disabled); the drives' own reaction to a lost master stops them", silent, missing);
    } else {
        snprintf(text, sizeof(text), "safe stop: brakes not confirmed: drive(s) %s not switch on disabled after %u "
                 "periods (--stop-timeout %g s); disabling them", missing, periods, opt->stop_timeout_s);
    }
    snprintf(st->safe_state, sizeof(st->safe_state), "%.230s", text + strlen("safe stop: "));
    telemetry_event(p->telem, p->k_published, st->braked ? "info" : "fault", text);
    /* disable voltage: a drive still in quick stop active (0x605A 5-8) closes its brake now */
    for (uint32_t i = 0; i < DISABLE_PERIODS_MAX; ++i) {
        stop_period(l, p, k++, ARM_CW_DISABLE_VOLTAGE, wait && silent == 0u);
        if (stopped_drives(l) == ALL_JOINTS || silent > 0u || opt->mode == MODE_LOCKSTEP) break;
    }
    for (int j = 0; j < ARM_N_JOINTS; ++j) st->statusword[j] = l->drives.statusword[j];
    st->periods = k - st->from_bus_period;
    return k;
}

void controller_run(const options_t *opt, const arm_robot_model_t *model, telemetry_t *telem,
                    run_report_t *report)
{
    static link_t l; /* static: the loop's working set is fixed at start-up */
    static loop_t p;
    memset(&l, 0, sizeof(l));
    memset(&p, 0, sizeof(p));
    memset(report, 0, sizeof(*report));
    l.report = report;
    l.spin_ns = (int64_t)(opt->spin_us * 1e3);
    l.canopen = opt->protocol_canopen;
    l.tpdo2_every = opt->tpdo2_type != 0u ? opt->tpdo2_type : 1u;
    l.heartbeat_ns = (int64_t)opt->co_heartbeat_ms * 1000000LL;
    l.master_id = opt->co_master_id;
    p.opt = opt;
    p.telem = telem;
    p.report = report;
    report->final_state = ARM_STATE_INIT;

    char err[200];
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        l.bus_of[j] = arm_can_bus_set_bus_of(&opt->buses, (unsigned)j);
    }
    if (arm_can_bus_set_open(&l.buses, &opt->buses, err, sizeof(err)) != 0) {
        snprintf(report->reason, sizeof(report->reason), "bus: %s", err);
        report->result = RUN_BUS_ERROR;
        return;
    }
    arm_bus_init(&l.drives);

    arm_ctl_config_t ctl_cfg = opt->ctl;
    if (l.canopen) { /* CiA 301: a synchronous RPDO (1-240) acts at the next SYNC; a TPDO2 sent every
                      * n-th SYNC stands for up to n - 1 periods after it (the core's torque check) */
        ctl_cfg.torque_report_lag_min = opt->rpdo_type <= 240u ? 2u : 1u;
        ctl_cfg.torque_report_lag_max = ctl_cfg.torque_report_lag_min + l.tpdo2_every - 1u;
        if (ctl_cfg.torque_report_lag_max > ARM_TORQUE_REPORT_LAG_MAX) ctl_cfg.torque_report_lag_max = ARM_TORQUE_REPORT_LAG_MAX;
    }
    const arm_ctl_init_result_t ir = arm_ctl_init(&p.ctl, model, &ctl_cfg);
    if (ir != ARM_CTL_OK) {
        snprintf(report->reason, sizeof(report->reason), "controller config: %s", arm_ctl_init_result_str(ir));
        report->result = RUN_FAULT;
        arm_can_bus_set_close(&l.buses);
        return;
    }

    const int64_t t_start = now_ns();
    if ((l.canopen ? boot_canopen(&l, opt, model, telem) : boot(&l, opt, model, telem)) != 0) {
        report->result = RUN_BOOT_FAILED;
        if (controller_stop_signal != 0) {
            snprintf(report->reason, sizeof(report->reason), "stopped by signal %d while the drives booted",
                     (int)controller_stop_signal);
            report->result = RUN_INTERRUPTED;
        }
        telemetry_event(telem, 0, "fault", report->reason);
        arm_can_frame_t stop; /* the drives that did come up: back to stopped */
        arm_bus_make_nmt(ARM_NMT_STOP, 0u, &stop);
        send_all(&l, &stop);
        arm_can_bus_set_close(&l.buses);
        report->wall_s = (double)(now_ns() - t_start) * 1e-9;
        return;
    }

    p.period_ns = (int64_t)(1e9 / opt->rate_hz);
    p.last_state = ARM_STATE_INIT;
    p.next_deadline = now_ns();
    report->result = RUN_OK;
    int enabling = 1;

    /* k counts bus periods (SYNCs); the first few bring the drives to operation enabled. Each
     * period: SYNC out, the drives' states in, then enable, or supervise, control and publish. */
    uint32_t k = 0;
    run_stop_cause_t cause = RUN_STOP_END;
    for (; p.k_run < opt->steps; ++k) {
        if (controller_stop_signal != 0) { /* at a period boundary: the stop begins with period k */
            snprintf(p.report->reason, sizeof(p.report->reason),
                     "stopped by signal %d after %u periods: drives quick-stopped under the hold, braked, disabled "
                     "and stopped", (int)controller_stop_signal, p.k_run);
            p.report->result = RUN_INTERRUPTED;
            telemetry_event(p.telem, p.k_run, "fault", p.report->reason);
            cause = RUN_STOP_SIGNAL;
            break;
        }
        if (p.task_over != 0) { /* the task ended, or stopped the arm itself (a fault): the controlled stop */
            if (p.task_over > 0) {
                snprintf(p.report->reason, sizeof(p.report->reason), "%s done after %u periods: the arm stopped",
                         task_name(opt->task), p.k_run);
                telemetry_event(p.telem, p.k_run, "info", p.report->reason);
            }
            cause = p.task_over > 0 ? RUN_STOP_END : RUN_STOP_FAULT;
            break;
        }
        const int64_t wake_latency = wait_for_period(&p);
        const int64_t cycle_start = now_ns();
        start_period(&l, k, period_time(&p, k, cycle_start));
        const int64_t wait_until = opt->mode == MODE_REALTIME
                                       ? p.next_deadline + p.period_ns * 8 / 10
                                       : cycle_start + (int64_t)(opt->lockstep_timeout_s * 1e9);
        if (!enabling) begin_timing(&l, k, wake_latency, wait_until);
        pump(&l, wait_until, states_done);
        if (l.late_on) lateness_missing(&l.late, ALL_JOINTS & ~l.drives.fresh_mask);
        if (enabling) {
            const int e = enable(&l, &p, k, l.drives.fresh_mask & ALL_JOINTS);
            if (e < 0) break;
            enabling = e == 0;
            if (paced(&p)) {
                p.next_deadline += p.period_ns;
            }
            continue;
        }
        supervise(&l, &p);
        const int64_t compute = control(&l, &p);
        if (publish(&p, k, wake_latency, compute, now_ns() - cycle_start) != 0) {
            cause = RUN_STOP_FAULT; /* this period's commands are out: the stop goes on with the next */
            ++k;
            break;
        }
    }
    const arm_state_t tracked = p.out.state;
    const arm_fault_t fault = p.out.fault;
    report->final_fault = fault;
    if (!enabling) {
        k = controlled_stop(&l, &p, k, cause);
    }
    for (unsigned s = 0; s < LATE_SIDES; ++s) {
        report->late_count[s] = l.late.count[s];
        report->late_worst_us[s] = l.late.worst_us[s];
    }

    /* Stop the drives (NMT): they are braked and disabled by now, or their own reaction takes over. */
    arm_can_frame_t stop;
    arm_bus_make_nmt(ARM_NMT_STOP, 0u, &stop);
    send_all(&l, &stop);
    if (p.task.opt != NULL) task_end(&p.task);
    /* a task that ended, as a stop signal, leaves the arm held by the stop (its tracking state otherwise) */
    report->final_state = cause == RUN_STOP_SIGNAL || (cause == RUN_STOP_END && p.task_over > 0) ? ARM_STATE_SAFE_STOP
                                                                                                : tracked;
    report->final_fault = fault;
    report->rx = l.drives.rx;
    for (unsigned b = 0; b < l.buses.n; ++b) {
        report->rx_undecodable += arm_can_bus_rx_undecodable(&l.buses.bus[b]);
        report->rx_kernel_drops += arm_can_bus_rx_kernel_drops(&l.buses.bus[b]);
    }
    report->wall_s = (double)(now_ns() - t_start) * 1e-9;
    arm_can_bus_set_close(&l.buses);
}
