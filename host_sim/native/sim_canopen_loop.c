#define _GNU_SOURCE
#include "sim_canopen_loop.h"

#include "sim_after_stop.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#define COB_SYNC 0x080u
#define COB_NMT 0x000u
#define STEPS_PER_SYNC_MAX 1000u /* 0x1006 beyond this many periods is clamped (a stall, not a cycle) */

struct co_sim {
    const sim_config_t *cfg;
    sim_arm_t *arm;
    sim_telemetry_t *tel;
    sim_report_t *rep;
    arm_can_bus_set_t set;
    int n;
    int bus_of[SIM_MAX_JOINTS];
    sim_co_node_t node[SIM_MAX_JOINTS];
    sim_servo_t servo[SIM_MAX_JOINTS];
    sim_rng_t noise[SIM_MAX_JOINTS];
    double tau[SIM_MAX_JOINTS];
    double w[SIM_MAX_JOINTS];
    uint16_t last_emcy[SIM_MAX_JOINTS];
    int64_t t0;
    /* the drives' clock: the wall clock until the master's first SYNC, then that moment plus the
     * periods simulated since (bus_now) */
    int64_t t_first_sync;
    uint64_t syncs[ARM_CAN_BUS_SET_MAX]; /* SYNCs handled per bus */
    unsigned held[ARM_CAN_BUS_SET_MAX];  /* a SYNC that came before its period's lead SYNC */
    int synced; /* a SYNC came: the next one ends a period */
    int ended; /* stepped (sim_co_service): the master stopped every drive */
    /* Bus timing (--bus-timing virtual): per bus, when each frame of the period would end on it.
     * A synchronous RPDO that would end after its period is held back and reaches its drive only
     * after the next SYNC, as on a real bus: the drive then acts on it one SYNC later. */
    int timed;
    sim_timeline_t timing[ARM_CAN_BUS_SET_MAX];
    double states_end; /* when the period's last TPDO ended, on any bus */
    double last_cmd[ARM_CAN_BUS_SET_MAX]; /* when the period's last RPDO ended on each bus (0: none yet) */
    arm_can_frame_t late[ARM_CAN_BUS_SET_MAX][SIM_MAX_JOINTS];
    unsigned n_late[ARM_CAN_BUS_SET_MAX];
    int holding_answers; /* TEST HOOK (cfg->late_answer_period): what the nodes queue stays queued */
    sim_plant_t *plant;  /* the truth the drives sense and act through, the brakes, the sessions (NULL: none) */
    const char *sessions_path;
    int serving;         /* --serve: each session's after-stop is the plant's own (sim_plant.h), not post_stop's */
    double frame_sent_s; /* the frame being handled: when the master sent it (-1: the bus does not say) */
    double sync_sent_s;  /* this period's lead SYNC: when it was sent, when it was read (-1: unknown) */
    double sync_read_s;
    double answered_s;   /* when the period's answers last went out */
    int prestepped;      /* the period since the last SYNC is simulated already (maybe_prestep) */
    int lost;            /* the master fell silent */
    int power_lost;      /* stopped by a signal: the drives lose their supply */
    int after_stop;      /* the master is gone: the arm runs on (post_stop), nothing is counted */
};

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* The drives' clock (their heartbeats, the master's heartbeat they watch): once the master's SYNC
 * has begun, the periods it paced, as a drive synchronised to it counts them. A run then gives the
 * same frames whatever the machine's load: in lockstep a stalled machine stalls the SYNC too, and
 * software in the loop runs faster or slower than the wall clock. (A master silent on the bus is
 * caught on the wall clock still: --idle-timeout, controller-lost.) */
static int64_t bus_now(co_sim_t *s)
{
    if (s->t_first_sync == 0) return mono_ns();
    return s->t_first_sync + (int64_t)((double)s->arm->step_count * s->arm->period * 1e9 + 0.5);
}

static void set_result(sim_report_t *rep, const char *result, const char *reason)
{
    if (strcmp(rep->result, "ok") == 0) {
        snprintf(rep->result, sizeof(rep->result), "%s", result);
        snprintf(rep->reason, sizeof(rep->reason), "%.390s", reason);
    }
}

static void captured(const co_sim_t *s, unsigned bus, const arm_can_frame_t *f)
{
    if (s->cfg->capture != NULL) {
        sim_capture_frame(s->cfg->capture, (double)s->arm->step_count * s->arm->period, bus, f);
    }
}

/* Every frame the nodes queued goes out on their bus, each bus's in one batch (one syscall on UDP:
 * the drives' answers leave together, as fast as the bus takes them); EMCYs are also telemetry events. */
static void flush(co_sim_t *s)
{
    if (s->holding_answers) return;
    static arm_can_frame_t batch[ARM_CAN_BUS_SET_MAX][SIM_MAX_JOINTS * SIM_CO_OUT_MAX];
    unsigned count[ARM_CAN_BUS_SET_MAX] = {0};
    for (int j = 0; j < s->n; ++j) {
        sim_co_node_t *nd = &s->node[j];
        const unsigned bus = (unsigned)s->bus_of[j];
        for (unsigned k = 0; k < nd->n_out; ++k) {
            const arm_can_frame_t *f = &nd->out[k];
            batch[bus][count[bus]++] = *f;
            if (f->id == 0x080u + nd->id) {
                char src[24], text[112];
                const unsigned code = (unsigned)(f->data[0] | (f->data[1] << 8));
                snprintf(src, sizeof(src), "drive%d", j + 1);
                snprintf(text, sizeof(text), "EMCY 0x%04x from node %u%s", code, nd->id,
                         code != 0u ? ": fault (its fault reaction, then its brake)" : ": error reset");
                sim_telemetry_event(s->tel, s->arm->step_count, src, code != 0u ? "fault" : "info", text);
            }
        }
        s->rep->tx_dropped += nd->out_dropped;
        nd->out_dropped = 0u;
        nd->n_out = 0u;
    }
    for (unsigned b = 0; b < s->set.n; ++b) {
        for (unsigned at = 0; at < count[b]; at += ARM_CAN_UDP_TX_BATCH) {
            const unsigned chunk = count[b] - at < ARM_CAN_UDP_TX_BATCH ? count[b] - at : ARM_CAN_UDP_TX_BATCH;
            const unsigned sent = arm_can_bus_set_send_many(&s->set, b, &batch[b][at], chunk);
            for (unsigned i = 0; i < sent; ++i) captured(s, b, &batch[b][at + i]);
            s->rep->frames_tx += sent;
            s->rep->tx_dropped += chunk - sent;
        }
    }
}

static int32_t fault_bits(const co_sim_t *s)
{
    int32_t m = 0;
    for (int j = 0; j < s->n; ++j) {
        if (s->node[j].power == SIM_PS_FAULT) m |= (int32_t)(1u << j);
    }
    return m;
}

/* ARM_SIM's flags: the brakes that hold, and whether the master is gone. */
static int32_t truth_flags(const co_sim_t *s)
{
    int32_t m = s->after_stop ? SIM_FLAG_AFTER_STOP : 0;
    for (int j = 0; j < s->n; ++j) {
        if (sim_power_stage_brake_nm(&s->node[j].ps) > 0.0) m |= (int32_t)(1u << j);
    }
    return m;
}

/* One period of the arm under the torques the drives' power stages apply. Nonzero: diverged. */
static int step_arm(co_sim_t *s)
{
    const int ideal = sim_servo_is_ideal(&s->cfg->servo);
    double cmd[SIM_MAX_JOINTS];
    for (int j = 0; j < s->n; ++j) {
        /* the drive's own velocity loop (a quick stop, its fault reaction) sees the joint as its encoder
         * does, and its torque reaches the joint as its motor turns (the plant's truth) */
        double qm = sim_arm_motor_q(s->arm, j), qdm = sim_arm_motor_qd(s->arm, j);
        if (s->plant != NULL) sim_plant_sense(s->plant, j, &qm, &qdm);
        cmd[j] = sim_co_node_period(&s->node[j], qdm, s->arm->period);
        sim_arm_set_brake(s->arm, j, sim_power_stage_brake_nm(&s->node[j].ps));
        s->tau[j] = ideal ? cmd[j]
                          : sim_servo_period_torque(&s->cfg->servo, &s->servo[j], cmd[j], 0.0, s->arm->period,
                                                    s->arm->data->qpos[j]);
        if (s->plant != NULL) s->tau[j] = sim_plant_actuate(s->plant, j, s->tau[j]);
    }
    const int bad = sim_arm_step(s->arm, s->tau, cmd, s->w);
    if (!s->after_stop) s->rep->periods++;
    sim_telemetry_truth(s->tel, s->arm->step_count - 1, s->arm->period, s->n, s->arm->data->qpos,
                        s->arm->data->qvel, s->tau, s->w, fault_bits(s), truth_flags(s));
    if (bad != 0) {
        char why[300];
        sim_arm_diverged_text(s->arm, bad, (unsigned long long)s->rep->periods, why, sizeof(why));
        set_result(s->rep, "diverged", why);
        for (int j = 0; j < s->n; ++j) sim_co_node_fault(&s->node[j], 0xFF00u, 0x80u);
    }
    return bad;
}

/* The arm advances by the first joint's communication cycle (0x1006), in whole periods. */
static void advance(co_sim_t *s)
{
    const double cycle_s = (double)sim_co_od_get(&s->node[0].od, 0x1006u, 0u) * 1e-6;
    unsigned steps = (unsigned)nearbyint(cycle_s / s->arm->period);
    steps = steps < 1u ? 1u : steps > STEPS_PER_SYNC_MAX ? STEPS_PER_SYNC_MAX : steps;
    for (unsigned k = 0; k < steps && step_arm(s) == 0; ++k) {
    }
}

/* A SYNC ends the period since the last one: the arm moves first, under the torques in effect
 * during it (a synchronous RPDO's from the last SYNC on, an event-driven one's from its arrival),
 * then each node takes its synchronous RPDOs and samples the state for its TPDOs. */
static void sync_nodes(co_sim_t *s, unsigned bus);

/* TEST HOOK: the held answers go out now, after what the master just sent. */
static void release_answers(co_sim_t *s)
{
    if (!s->holding_answers) return;
    s->holding_answers = 0;
    flush(s);
}

static uint64_t bin_of(double us)
{
    return us < 0.0 ? 0u : us >= (double)SIM_COST_BINS ? SIM_COST_BINS : (uint64_t)us;
}

/* The period that just ended: how long after the master sent its SYNC the drives read it and their
 * answers went out (where the bus says when it was sent). */
static void record_answer(co_sim_t *s)
{
    sim_report_t *r = s->rep;
    if (s->sync_sent_s < 0.0 || s->answered_s < 0.0 || s->after_stop) return;
    const double read_us = (s->sync_read_s - s->sync_sent_s) * 1e6, answer_us = (s->answered_s - s->sync_sent_s) * 1e6;
    r->read_hist[bin_of(read_us)]++;
    r->answer_hist[bin_of(answer_us)]++;
    r->answer_n++;
    if (read_us > r->read_max_us) r->read_max_us = read_us;
    if (answer_us > r->answer_max_us) r->answer_max_us = answer_us;
    int64_t *row = r->answer_last[r->answer_last_n++ % SIM_ANSWER_LAST];
    row[0] = (int64_t)s->syncs[s->bus_of[0]] - 2; /* the bus period of the SYNC before this one */
    row[1] = (int64_t)read_us;
    row[2] = (int64_t)answer_us;
    s->answered_s = -1.0;
}

/* Once every bus's drives have answered this period's SYNC, the arm is stepped through the period
 * at once, under the torques in effect from this SYNC on (each drive's synchronous RPDOs took effect
 * at it), instead of when the next SYNC comes: the next period's answers then go out the moment its
 * SYNC is read, the physics off their path. Not where a drive's RPDO is event-driven (its torque
 * changes when the frame comes, inside the period). */
static void maybe_prestep(co_sim_t *s)
{
    if (!s->synced || s->prestepped) return;
    const unsigned lead = (unsigned)s->bus_of[0];
    for (unsigned b = 0; b < s->set.n; ++b) {
        if (s->syncs[b] != s->syncs[lead]) return;
    }
    for (int j = 0; j < s->n; ++j) {
        const sim_co_pdo_t *r = &s->node[j].rpdo[0];
        if (r->valid && r->trans >= 254u) return;
    }
    advance(s);
    s->prestepped = 1;
}

static void on_sync(co_sim_t *s, unsigned bus)
{
    /* Every bus's SYNC of a period follows the first joint's bus's, which moves the arm. Sockets
     * keep no order between buses: another bus's SYNC that comes first waits for it. */
    const unsigned lead_bus = (unsigned)s->bus_of[0];
    if (bus != lead_bus) {
        if (s->syncs[bus] >= s->syncs[lead_bus] && s->held[bus] == 0u) {
            s->held[bus] = 1u; /* restored, not an error: the controller sent the lead SYNC first */
            return;
        }
        s->syncs[bus]++;
        sync_nodes(s, bus);
        maybe_prestep(s);
        return;
    }
    s->syncs[bus]++;
    record_answer(s);
    s->sync_read_s = arm_can_bus_clock_s();
    /* the master's time, where it is one (a python-can master may leave its timestamps at 0) */
    const double age = s->sync_read_s - s->frame_sent_s;
    s->sync_sent_s = s->frame_sent_s >= 0.0 && age >= -0.001 && age <= 0.5 ? s->frame_sent_s : -1.0;
    if (!sim_keeps_holding(s->cfg, s->syncs[bus] - 1u)) release_answers(s);
    s->holding_answers = sim_answers_late(s->cfg, s->syncs[bus] - 1u);
    if (s->synced && !s->prestepped) advance(s);
    s->prestepped = 0;
    s->synced = 1;
    s->states_end = 0.0;
    sync_nodes(s, bus);
    for (unsigned b = 0; b < s->set.n; ++b) {
        if (b != lead_bus && s->held[b] != 0u) {
            s->held[b] = 0u;
            s->syncs[b]++;
            sync_nodes(s, b);
        }
    }
    maybe_prestep(s);
}

/* Bus timing: this bus's SYNC at the period's start, then the TPDOs the nodes just queued, in id
 * order once the SYNC has ended. */
static void period_done(co_sim_t *s, unsigned bus)
{
    sim_bus_stats_t *st = &s->timing[bus].stats;
    if (s->last_cmd[bus] <= 0.0) return;
    st->periods++;
    st->sync_to_last_cmd_sum_s += s->last_cmd[bus];
    if (s->last_cmd[bus] > st->sync_to_last_cmd_max_s) st->sync_to_last_cmd_max_s = s->last_cmd[bus];
    s->last_cmd[bus] = 0.0;
}

static void time_sync(co_sim_t *s, unsigned bus)
{
    sim_timeline_t *tl = &s->timing[bus];
    period_done(s, bus);
    sim_timeline_new_period(tl, s->arm->period);
    const uint32_t sync_id = COB_SYNC;
    double sync_end;
    sim_timeline_transmit(tl, 0.0, &sync_id, 1u, &sync_end);
    uint32_t ids[SIM_BATCH_MAX];
    unsigned k = 0;
    for (int j = 0; j < s->n; ++j) {
        const sim_co_node_t *nd = &s->node[j];
        if (s->bus_of[j] != (int)bus) continue;
        for (unsigned i = 0; i < nd->n_out && k < SIM_BATCH_MAX; ++i) ids[k++] = nd->out[i].id;
    }
    double ends[SIM_BATCH_MAX];
    sim_timeline_transmit(tl, sync_end, ids, k, ends);
    for (unsigned i = 0; i < k; ++i) s->states_end = ends[i] > s->states_end ? ends[i] : s->states_end;
}

static void sync_nodes(co_sim_t *s, unsigned bus)
{
    const double *q = s->arm->data->qpos, *qd = s->arm->data->qvel;
    for (int j = 0; j < s->n; ++j) {
        if (s->bus_of[j] != (int)bus) continue;
        double qm = q[j], qdm = qd[j], taum = NAN;
        if (!sim_servo_is_ideal(&s->cfg->servo)) {
            sim_servo_measure(&s->cfg->servo, &s->servo[j], &s->noise[j], q[j], qd[j], sim_arm_motor_q(s->arm, j),
                              sim_arm_motor_qd(s->arm, j), s->arm->period, &qm, &qdm, &taum);
        }
        if (s->plant != NULL) sim_plant_sense(s->plant, j, &qm, &qdm);
        sim_co_node_on_sync(&s->node[j], qm, qdm, taum);
    }
    if (s->timed) {
        time_sync(s, bus);
        for (unsigned i = 0; i < s->n_late[bus]; ++i) { /* last period's late RPDOs, after this SYNC */
            for (int j = 0; j < s->n; ++j) {
                if (s->bus_of[j] == (int)bus) sim_co_node_on_frame(&s->node[j], &s->late[bus][i], bus_now(s));
            }
        }
        s->n_late[bus] = 0u;
    }
    flush(s);
    if (!s->holding_answers) s->answered_s = arm_can_bus_clock_s();
}

/* Bus timing: an RPDO of a node on this bus, from the master, goes on the bus once every TPDO of
 * the period has ended (plus the controller's latency); 1 if it would end after its period, when
 * it is held back for the next SYNC. */
static int is_rpdo(const co_sim_t *s, const arm_can_frame_t *f, unsigned bus)
{
    for (int j = 0; j < s->n; ++j) {
        if (s->bus_of[j] == (int)bus && f->id == 0x200u + s->node[j].id) return 1;
    }
    return 0;
}

static int rpdo_late(co_sim_t *s, const arm_can_frame_t *f, unsigned bus)
{
    if (!is_rpdo(s, f, bus) || !s->synced) return 0;
    sim_timeline_t *tl = &s->timing[bus];
    double end;
    sim_timeline_transmit(tl, s->states_end + s->cfg->controller_latency_s, &f->id, 1u, &end);
    if (end > s->last_cmd[bus]) s->last_cmd[bus] = end;
    if (end <= s->arm->period || s->n_late[bus] >= SIM_MAX_JOINTS) return 0;
    s->late[bus][s->n_late[bus]++] = *f;
    s->rep->commands_late++;
    if (++tl->stats.commands_late == 1u) { /* the first one says so; the count says the rest */
        char src[24], text[200];
        snprintf(src, sizeof(src), "bus%u", bus);
        snprintf(text, sizeof(text), "bus timing: RPDO 0x%03x ended %.3f ms after its SYNC, after its %g ms period: "
                 "its drive acts on it one SYNC late (bus overloaded?)", (unsigned)f->id, end * 1e3,
                 s->arm->period * 1e3);
        sim_telemetry_event(s->tel, s->arm->step_count, src, "warning", text);
    }
    return 1;
}

static int all_stopped(const co_sim_t *s)
{
    for (int j = 0; j < s->n; ++j) {
        if (s->node[j].nmt != SIM_NMT_STATE_STOPPED) return 0;
    }
    return 1;
}

/* One frame from the bus: the master's (SYNC, NMT, SDO, RPDO, heartbeat) to the nodes on its bus;
 * the drives' own, heard back, counted. 1 when the master has stopped every drive. */
static int on_frame(co_sim_t *s, const arm_can_frame_t *f, unsigned bus, int64_t now)
{
    sim_report_t *rep = s->rep;
    int own = 0;
    for (int j = 0; j < s->n && !own; ++j) own = s->bus_of[j] == (int)bus && sim_co_node_sends(&s->node[j], f->id);
    captured(s, bus, f);
    if (own) {
        rep->rx_foreign_drive++; /* a drive's frame heard back (UDP), or another node's */
        return 0;
    }
    rep->frames_rx++;
    if ((f->flags & (ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_ERR | ARM_CAN_FLAG_EXT | ARM_CAN_FLAG_FD)) != 0u) {
        rep->rx_bad_frame++; /* classic 11-bit data frames only */
    } else if (f->id == COB_SYNC) {
        if (s->t_first_sync == 0) s->t_first_sync = now;
        if (f->len <= 1u) on_sync(s, bus);
        else rep->rx_bad_frame++;
    } else {
        if (f->id == COB_NMT && f->len == 2u && f->data[0] == 0x02u && f->data[1] == 0u && s->synced) {
            /* NMT stop to all (on whichever bus it is read first) ends the last period, as the next SYNC
             * would have, before any drive stops applying its torque */
            if (!s->prestepped) advance(s);
            s->synced = 0;
            s->prestepped = 0;
        }
        /* An RPDO on a bus whose SYNC of this period came: the master's command for this period. */
        if (s->cfg->late_answer_release == SIM_LATE_AT_COMMAND && is_rpdo(s, f, bus) &&
            s->syncs[bus] == s->syncs[s->bus_of[0]]) {
            release_answers(s);
        }
        if (s->timed && rpdo_late(s, f, bus)) return 0;
        for (int j = 0; j < s->n; ++j) {
            if (s->bus_of[j] == (int)bus) sim_co_node_on_frame(&s->node[j], f, now);
        }
    }
    return f->id == COB_NMT && all_stopped(s);
}

static void tick_all(co_sim_t *s, int64_t now)
{
    const double sim_s = (double)s->arm->step_count * s->arm->period;
    for (int j = 0; j < s->n; ++j) sim_co_node_tick(&s->node[j], now, sim_s);
    flush(s);
}

/* The longest the loop may sleep: a stop request is noticed within 100 ms, the nodes' timers kept. */
static int64_t wait_ns(co_sim_t *s)
{
    const int64_t now = bus_now(s);
    int64_t wait = 100000000;
    for (int j = 0; j < s->n; ++j) {
        const int64_t w = sim_co_node_wait_ns(&s->node[j], now);
        if (w < wait) wait = w;
    }
    return wait;
}

/* Waits up to wait_ns for a frame and hands what came to the nodes, in the order it was sent (see
 * below), then their timers. -1 on a bus error (the result set); 1 when the master stopped every
 * drive; else 0. *master: a frame of the master's came. */
static int receive(co_sim_t *s, int64_t wait, int *master)
{
    sim_report_t *rep = s->rep;
    *master = 0;
    arm_can_frame_t f;
    unsigned bus = 0;
    const int rc = arm_can_bus_set_recv(&s->set, &f, &bus, (int)(wait / 1000));
    const double f_sent_s = rc == 1 ? arm_can_bus_set_sent_s(&s->set, bus) : -1.0;
    if (rc < 0) {
        char text[200];
        snprintf(text, sizeof(text), "receiving on bus %u failed: %s", bus, strerror(errno));
        set_result(rep, "bus-error", text);
        return -1;
    }
    const int64_t now = bus_now(s);
    const uint64_t before = rep->frames_rx;
    int stopped = 0;
    /* SYNC and NMT go on every bus, and sockets keep no order between buses: what is already
     * queued on the others up to their own SYNC (this period's RPDOs) was sent first; their
     * SYNC and what follows it come after this frame. */
    static arm_can_frame_t later[ARM_CAN_BUS_SET_MAX][64];
    static double later_sent_s[ARM_CAN_BUS_SET_MAX][64];
    unsigned n_later[ARM_CAN_BUS_SET_MAX] = {0};
    if (rc == 1 && (f.id == COB_SYNC || f.id == COB_NMT) && s->set.n > 1u) {
        for (unsigned i = 0; i < s->set.n && !stopped; ++i) {
            arm_can_frame_t g;
            while (i != bus && n_later[i] < 64u && !stopped && arm_can_bus_recv(&s->set.bus[i], &g, 0) == 1) {
                if (n_later[i] > 0u || g.id == COB_SYNC || g.id == COB_NMT) {
                    later_sent_s[i][n_later[i]] = s->set.bus[i].rx_sent_s;
                    later[i][n_later[i]++] = g;
                } else {
                    s->frame_sent_s = s->set.bus[i].rx_sent_s;
                    stopped = on_frame(s, &g, i, now);
                }
            }
        }
    }
    if (rc == 1 && !stopped) {
        s->frame_sent_s = f_sent_s;
        stopped = on_frame(s, &f, bus, now);
    }
    for (unsigned i = 0; i < s->set.n; ++i) {
        for (unsigned k = 0; k < n_later[i] && !stopped; ++k) {
            s->frame_sent_s = later_sent_s[i][k];
            stopped = on_frame(s, &later[i][k], i, now);
        }
    }
    *master = rep->frames_rx != before;
    tick_all(s, bus_now(s)); /* the frames may have ended a period */
    return stopped;
}

static void run(co_sim_t *s)
{
    const sim_config_t *cfg = s->cfg;
    sim_report_t *rep = s->rep;
    int64_t last_rx = mono_ns();
    int booted = 0;
    for (;;) {
        if (sim_stop_requested) {
            set_result(rep, "interrupted", "stopped by a signal");
            s->power_lost = 1;
            return;
        }
        int master = 0;
        const int rc = receive(s, wait_ns(s), &master);
        const int64_t wall = mono_ns();
        if (master) {
            last_rx = wall;
            booted = 1;
        }
        if (rc > 0) s->ended = 1; /* the master stopped every drive */
        if (rc != 0) return;      /* that, or a bus error */
        const double timeout = booted ? cfg->idle_timeout_s : cfg->boot_timeout_s;
        if ((double)(wall - last_rx) * 1e-9 > timeout) {
            char why[160];
            snprintf(why, sizeof(why), "%s for %g s: drives faulted, torque off",
                     booted ? "master silent" : "no master on the bus", timeout);
            set_result(rep, "controller-lost", why);
            s->lost = 1; /* the drives fault once the arm has run on after the stop (post_stop) */
            return;
        }
    }
}

/* --serve: the sessions' record, and the plant's line about a finished one (on stdout: armctl plant shows it). */
static void sessions_changed(co_sim_t *s, const char *event)
{
    char err[300];
    if (event != NULL) {
        printf("arm_sim: %s\n", event);
        fflush(stdout);
        sim_telemetry_event(s->tel, s->arm->step_count, "plant", "info", event);
    }
    if (s->sessions_path != NULL && s->sessions_path[0] != '\0' &&
        sim_plant_write(s->plant, s->sessions_path, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
    }
}

/* At most this many periods are simulated at once between sessions: a machine that could not keep
 * up for longer drops the rest (counted: idle_slips) rather than run the physics in a burst. */
#define IDLE_CATCH_UP_MAX 200u

/* --serve: masters come and go (sim_plant.h). While one runs its SYNCs the arm moves on them, as
 * in run(); between masters, on the wall clock, with the drives' brakes; while a master boots (it
 * speaks, no SYNC yet) the arm waits for its first SYNC. Ends on a signal. */
static void serve(co_sim_t *s)
{
    const sim_config_t *cfg = s->cfg;
    sim_plant_t *p = s->plant;
    const int64_t period_ns = (int64_t)(s->arm->period * 1e9 + 0.5);
    int64_t last_rx = mono_ns();
    int master = 0; /* a master has spoken since the last session ended */
    int64_t idle_anchor = mono_ns();
    uint64_t idle_done = 0u;
    int64_t prev_wall = mono_ns();
    char text[400];
    sessions_changed(s, "the arm is on the bus: waiting for a master");
    for (;;) {
        if (sim_stop_requested) {
            set_result(s->rep, "interrupted", "stopped by a signal");
            return;
        }
        const int idle = !p->in_session && !master;
        int64_t wait = wait_ns(s);
        if (idle && wait > period_ns) wait = period_ns;
        int spoke = 0;
        const int rc = receive(s, wait, &spoke);
        if (rc < 0) return;
        const int64_t wall = mono_ns();
        if (master && !p->in_session) s->t_first_sync += wall - prev_wall; /* a master boots: the drives' clock runs on */
        prev_wall = wall;
        if (spoke) {
            last_rx = wall;
            master = 1;
        }
        if (!p->in_session && s->synced) {
            sim_plant_session_begin(p, (uint64_t)s->arm->step_count);
            snprintf(text, sizeof(text), "session %d: a master runs its SYNC", p->n_sessions);
            sessions_changed(s, text);
        }
        const int silent = master && (double)(wall - last_rx) * 1e-9 > cfg->idle_timeout_s;
        if (rc == 1 || silent) { /* the master stopped every drive, or fell silent: the arm is on its own */
            const int ran = p->in_session;
            if (ran) sim_plant_session_end(p, (uint64_t)s->arm->step_count, rc == 1 ? "stopped" : "master silent");
            s->synced = 0; /* the next master's first SYNC begins a period, ends none */
            master = 0;
            idle_anchor = wall;
            idle_done = 0u;
            snprintf(text, sizeof(text), "%s%s: the drives are disabled, the brakes hold the arm",
                     rc == 1 ? "the master stopped the drives" : "the master fell silent", ran ? "" : " before its first SYNC");
            sessions_changed(s, text);
        }
        if (!p->in_session && !master) { /* between masters: the wall clock moves the arm */
            uint64_t due = (uint64_t)((wall - idle_anchor) / period_ns);
            if (due > idle_done + IDLE_CATCH_UP_MAX) {
                p->idle_slips++;
                idle_done = due - IDLE_CATCH_UP_MAX;
            }
            for (; idle_done < due; ++idle_done) {
                if (step_arm(s) != 0) {
                    sessions_changed(s, s->rep->reason);
                    return;
                }
                p->idle_steps++;
                if (sim_plant_after_step(p)) {
                    sim_plant_describe(p, sim_plant_last(p), text, sizeof(text));
                    sessions_changed(s, text);
                }
            }
            tick_all(s, bus_now(s));
        }
    }
}

static co_sim_t g_sim;

co_sim_t *sim_co_begin(const sim_config_t *cfg, const sim_co_config_t *co, sim_arm_t *arm, sim_telemetry_t *tel,
                       sim_report_t *rep, char *err, unsigned long errcap)
{
    co_sim_t *sp = &g_sim;
    memset(sp, 0, sizeof(*sp));
    memset(rep, 0, sizeof(*rep));
    snprintf(rep->result, sizeof(rep->result), "ok");
    sp->cfg = cfg;
    sp->arm = arm;
    sp->tel = tel;
    sp->rep = rep;
    sp->n = arm->n;
    sp->t0 = mono_ns();
    sp->timed = cfg->timing != SIM_TIMING_OFF;
    sp->plant = co->plant;
    sp->sessions_path = co->sessions_path;
    if (co->serve && co->plant == NULL) {
        snprintf(err, errcap, "--serve: the plant is missing");
        return NULL;
    }
    sp->serving = co->serve;
    if (co->serve) sp->t_first_sync = sp->t0; /* the drives' clock is the plant's from the start (bus_now) */
    sp->frame_sent_s = sp->sync_sent_s = sp->answered_s = -1.0;
    memcpy(sp->timing, cfg->timelines, sizeof(sp->timing));
    for (int j = sp->n; j < SIM_MAX_JOINTS; ++j) {
        const sim_co_preset_t *own = &co->node_preset[j];
        if (own->rated_torque_mnm || own->encoder_increments || own->gear_motor || own->gear_efficiency > 0.0 ||
            own->max_torque_permille) {
            snprintf(err, errcap, "--node %d: the arm has %d drives", j + 1, sp->n);
            return NULL;
        }
    }
    for (int j = 0; j < sp->n; ++j) {
        sp->bus_of[j] = arm_can_bus_set_bus_of(&cfg->buses, (unsigned)j);
        if (sp->bus_of[j] < 0) {
            snprintf(err, errcap, "--bus: drive %d is on no bus", j + 1);
            return NULL;
        }
        const uint8_t id = (uint8_t)(j + 1);
        sim_co_preset_t pre = co->preset;
        const sim_co_preset_t *own = &co->node_preset[j];
        if (own->rated_torque_mnm) pre.rated_torque_mnm = own->rated_torque_mnm;
        if (own->torque_units_per_nm) pre.torque_units_per_nm = own->torque_units_per_nm;
        if (own->gear_efficiency > 0.0) pre.gear_efficiency = own->gear_efficiency;
        if (own->encoder_increments) pre.encoder_increments = own->encoder_increments;
        if (own->quick_stop_decel) pre.quick_stop_decel = own->quick_stop_decel;
        if (own->max_torque_permille) pre.max_torque_permille = own->max_torque_permille;
        if (own->gear_motor) {
            pre.gear_motor = own->gear_motor;
            pre.gear_shaft = own->gear_shaft;
        }
        const sim_co_table_t *table = co->table != NULL ? co->table : sim_co_table_builtin();
        if (table == NULL) {
            snprintf(err, errcap, "the build's own object dictionary table does not parse (gen/eds.py)");
            return NULL;
        }
        char why[300];
        if (sim_co_node_init(&sp->node[j], table, id, &pre, arm->torque_limit[j],
                             co->overcurrent_node == id ? co->overcurrent_at_s : -1.0, why, sizeof(why)) != 0) {
            snprintf(err, errcap, "--protocol canopen: %s", why);
            return NULL;
        }
        sim_co_node_set_stopping(&sp->node[j], &cfg->brake[j], arm->drive_inertia[j], cfg->quick_stop_decel);
        if (cfg->brakes_released_at_start) sim_power_stage_release_brake(&sp->node[j].ps);
        sim_arm_set_brake(arm, j, sim_power_stage_brake_nm(&sp->node[j].ps));
        sim_servo_init(&sp->servo[j]);
        sim_rng_seed(&sp->noise[j], arm->unc.seed ^ (0x9E3779B97F4A7C15ull * ((uint64_t)j + 1u)));
    }
    if (arm_can_bus_set_open(&sp->set, &cfg->buses, err, errcap) != 0) return NULL;
    for (int j = 0; j < sp->n; ++j) sim_co_node_boot(&sp->node[j], sp->t0);
    flush(sp);
    char text[700];
    snprintf(text, sizeof(text), "%d CANopen CiA 402 drives (nodes 1..%d) up on bus %s", sp->n, sp->n, cfg->bus_text);
    sim_telemetry_event(tel, 0, "sim", "info", text);
    return sp;
}

int sim_co_service(co_sim_t *s)
{
    arm_can_frame_t f;
    unsigned bus = 0;
    while (!s->ended && arm_can_bus_set_recv(&s->set, &f, &bus, 0) == 1) {
        s->frame_sent_s = arm_can_bus_set_sent_s(&s->set, bus);
        s->ended = on_frame(s, &f, bus, bus_now(s));
    }
    if (!s->ended) tick_all(s, bus_now(s));
    return !s->ended;
}

/* After the master stopped the drives, fell silent or the simulator was stopped: the arm runs on
 * for --post-stop s of simulated time, as fast as it computes, each drive on its own clock (its
 * heartbeat consumer, its fault reaction, its brake; the supply cut when the simulator was stopped
 * by a signal). Its truth goes on in ARM_SIM (SIM_FLAG_AFTER_STOP); the run's own counts stop. */
static void post_stop(co_sim_t *s, const char *why)
{
    double q0[SIM_MAX_JOINTS];
    const uint64_t periods = sim_after_stop_begin(s->rep, s->cfg, s->arm, s->tel, why, q0);
    s->after_stop = 1;
    s->holding_answers = 0;
    if (s->power_lost) {
        for (int j = 0; j < s->n; ++j) sim_co_node_power_lost(&s->node[j]);
    }
    for (uint64_t k = 0; k < periods; ++k) {
        tick_all(s, bus_now(s)); /* the drives' own timers: the master's heartbeat they watch */
        const int bad = step_arm(s);
        sim_after_stop_period(s->rep, s->arm, q0);
        if (bad != 0) break;
    }
    tick_all(s, bus_now(s));
    for (int j = 0; j < s->n; ++j) {
        sim_after_stop_drive(s->rep, j, (uint16_t)s->node[j].power, sim_power_stage_brake_nm(&s->node[j].ps) > 0.0);
    }
}

void sim_co_end(co_sim_t *s)
{
    sim_report_t *rep = s->rep;
    /* the run's drive faults: those of the stop; a drive that faults after it (its heartbeat
     * consumer, once the master stopped heartbeating) is post_stop's to say */
    for (int j = 0; j < s->n; ++j) {
        if (s->node[j].power == SIM_PS_FAULT || s->node[j].power == SIM_PS_FAULT_REACTION) rep->drive_fault_mask |= 1u << j;
    }
    if (!s->serving && s->cfg->post_stop_s > 0.0 && s->t_first_sync != 0 && strcmp(rep->result, "diverged") != 0) {
        post_stop(s, s->power_lost ? "the simulator was stopped: the drives lost their supply"
                     : s->lost     ? "the master fell silent"
                     : s->ended    ? "the master stopped the drives (NMT stop)"
                                   : "the bus failed");
    }
    if (s->lost) { /* the master was lost: every drive faulted, on its own or now */
        for (int j = 0; j < s->n; ++j) sim_co_node_fault(&s->node[j], SIM_CO_EMCY_HEARTBEAT, 0x10u);
        flush(s);
        for (int j = 0; j < s->n; ++j) rep->drive_fault_mask |= 1u << j;
    }
    for (unsigned b = 0; b < s->set.n; ++b) {
        rep->rx_undecodable += arm_can_bus_rx_undecodable(&s->set.bus[b]);
        rep->rx_kernel_drops += arm_can_bus_rx_kernel_drops(&s->set.bus[b]);
    }
    rep->n_buses = s->set.n;
    for (unsigned b = 0; b < s->set.n; ++b) {
        period_done(s, b);
        rep->bus_stats[b] = s->timing[b].stats;
    }
    rep->wall_s = (double)(mono_ns() - s->t0) * 1e-9;
    sim_telemetry_event(s->tel, s->arm->step_count, "sim", rep->reason[0] ? "fault" : "info",
                        rep->reason[0] ? rep->reason : "stopped by the master (NMT stop)");
    arm_can_bus_set_close(&s->set);
}

int sim_canopen_run(const sim_config_t *cfg, const sim_co_config_t *co, sim_arm_t *arm, sim_telemetry_t *tel,
                    sim_report_t *rep, char *err, unsigned long errcap)
{
    co_sim_t *s = sim_co_begin(cfg, co, arm, tel, rep, err, errcap);
    if (s == NULL) return -1;
    if (co->serve) {
        serve(s);
    } else {
        run(s);
    }
    sim_co_end(s);
    return 0;
}
