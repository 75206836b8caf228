#define _GNU_SOURCE
#include "sim_loop.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "arm_drives.h"
#include "sim_after_stop.h"
#include "sim_drive.h"
#include "sim_frames.h"

#define HEARTBEAT_PERIODS 100
#define STOP_CHECK_S 0.1 /* a stop request is noticed within this */
/* A SYNC or NMT read fresh (the ring is then empty) puts back up to EARLIER_MAX frames already
 * queued on the other buses, and itself: the ring holds all of them, so that path cannot overflow.
 * requeue_deferred also runs on an empty ring only (at most ARM_CAN_BUS_SET_MAX frames). */
#define EARLIER_MAX 256u
#define PENDING_MAX (EARLIER_MAX + 1u)

volatile sig_atomic_t sim_stop_requested = 0;

typedef struct {
    unsigned bus;
    arm_can_frame_t f;
    int flag; /* 0 fresh, 1 other buses already drained for it, 2 that and never held back again */
} queued_t;

#define HELD_MAX (2u * SIM_LATE_BURST_MAX * SIM_MAX_JOINTS) /* a burst's answers, and an EMCY or heartbeat beside each */

/* The whole working set: static, sized at compile time, nothing allocated per period. */
struct sim {
    const sim_config_t *cfg;
    sim_arm_t *arm;
    sim_telemetry_t *tel;
    sim_report_t *rep;
    int n;
    arm_can_bus_set_t set;
    int bus_of[SIM_MAX_JOINTS];
    sim_drive_t drives[SIM_MAX_JOINTS];
    sim_servo_t servo[SIM_MAX_JOINTS]; /* each drive's sensing and torque path (cfg->servo) */
    sim_rng_t noise[SIM_MAX_JOINTS];   /* each drive's measurement noise: a seeded stream per drive, so
                                        * the order the buses are served in does not change a run */
    sim_timeline_t timing[ARM_CAN_BUS_SET_MAX]; /* when cfg->timing != off */
    int counter;     /* SYNC counter of the period being served, -1: none */
    int last_sync[ARM_CAN_BUS_SET_MAX]; /* each bus's last SYNC counter, -1: none yet */
    uint32_t synced; /* bit b: this period's SYNC arrived on bus b */
    uint32_t got_cmd;
    uint16_t cmd_cw[SIM_MAX_JOINTS];
    double cmd_tau[SIM_MAX_JOINTS];
    double last_w[SIM_MAX_JOINTS];
    double last_tau[SIM_MAX_JOINTS];
    int64_t period_wall_ns; /* wallclock timing: when the period's first SYNC arrived */
    double states_end;      /* bus timing: when the last state frame of the period ended */
    queued_t pending[PENDING_MAX]; /* ring: frames read but not handled yet */
    unsigned pend_head, pend_len;
    queued_t deferred[ARM_CAN_BUS_SET_MAX];
    unsigned n_deferred;
    int64_t first_sync_ns;
    int64_t last_period_ns;
    int64_t cpu_mark_ns; /* thread CPU time at the end of the previous period */
    int truth_pending;   /* the last period's ARM_SIM message is still to be published */
    int32_t truth_faults;
    int32_t truth_flags;
    int lost;            /* the controller fell silent */
    int after_stop;      /* the controller is gone: the arm runs on (post_stop), nothing is counted */
    int power_lost;      /* stopped by a signal: the drives lose their supply */
    int64_t t0_ns;       /* when the drives booted */
    int booted;          /* the controller has spoken (NMT or SYNC) */
    int ended;           /* the controller stopped every drive */
    /* TEST HOOK (cfg->late_answer_period): what the drives send while their answers are held back */
    int holding_answers;
    queued_t held[HELD_MAX];
    unsigned n_held;
};

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static int64_t cpu_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* --profile: thread CPU time per activity. A mark, then the time since it added to one counter. */
static int64_t prof_mark(const sim_t *s)
{
    return s->cfg->profile ? cpu_ns() : 0;
}

/* The profile breaks down the run's periods (those rep->periods counts), not the physics the
 * simulator runs on after the stop: counted there, a part would outgrow the period's cost. */
static void prof_add(const sim_t *s, uint64_t *counter, int64_t mark)
{
    if (s->cfg->profile && !s->after_stop) *counter += (uint64_t)(cpu_ns() - mark);
}

static uint32_t all_joints(const sim_t *s)
{
    return (uint32_t)((1ull << s->n) - 1u);
}

/* ---- telemetry ---------------------------------------------------------------------------- */
static void event(sim_t *s, const char *source, const char *level, const char *text)
{
    const int64_t c0 = prof_mark(s);
    sim_telemetry_event(s->tel, s->arm->step_count, source, level, text);
    prof_add(s, &s->rep->prof_telemetry_ns, c0);
}

/* ARM_SIM's flags: the brakes that hold, and whether the controller is gone. */
static int32_t truth_flags(const sim_t *s)
{
    int32_t m = s->after_stop ? SIM_FLAG_AFTER_STOP : 0;
    for (int j = 0; j < s->n; ++j) {
        if (sim_power_stage_brake_nm(&s->drives[j].ps) > 0.0) m |= (int32_t)(1u << j);
    }
    return m;
}

static int32_t fault_bits(const sim_t *s)
{
    int32_t m = 0;
    for (int j = 0; j < s->n; ++j) {
        if (s->drives[j].error_code != 0u) m |= (int32_t)(1u << j);
    }
    return m;
}

/* ---- bus ---------------------------------------------------------------------------------- */
static void captured(const sim_t *s, unsigned bus, const arm_can_frame_t *f)
{
    if (s->cfg->capture != NULL) {
        sim_capture_frame(s->cfg->capture, (double)s->arm->step_count * s->arm->period, bus, f);
    }
}

/* A frame only drives send, from another node on the bus: on the wire, not for the drives. */
static void foreign(sim_t *s, unsigned bus, const arm_can_frame_t *f)
{
    s->rep->rx_foreign_drive++;
    captured(s, bus, f);
}

/* TEST HOOK (--debug-lose-bus I@PERIOD): the bus is lost from that period on (nothing sent). */
static int bus_lost(const sim_t *s, unsigned bus)
{
    return s->cfg->lose_bus >= 0 && (unsigned)s->cfg->lose_bus == bus && s->rep->periods >= s->cfg->lose_bus_from;
}

static void send(sim_t *s, unsigned bus, const arm_can_frame_t *f)
{
    if (bus_lost(s, bus)) {
        s->rep->tx_dropped++;
        return;
    }
    if (s->holding_answers && s->n_held < HELD_MAX) {
        s->held[s->n_held++] = (queued_t){.bus = bus, .f = *f};
        return;
    }
    const int64_t c0 = prof_mark(s);
    if (arm_can_bus_set_send(&s->set, bus, f) == 0) {
        s->rep->frames_tx++;
        captured(s, bus, f);
    } else {
        s->rep->tx_dropped++;
    }
    prof_add(s, &s->rep->prof_bus_tx_ns, c0);
}

static void send_batch(sim_t *s, unsigned bus, const arm_can_frame_t *frames, unsigned n)
{
    if (n == 0u) return;
    if (bus_lost(s, bus)) {
        s->rep->tx_dropped += n;
        return;
    }
    if (s->holding_answers) {
        for (unsigned i = 0; i < n; ++i) send(s, bus, &frames[i]);
        return;
    }
    const int64_t c0 = prof_mark(s);
    const unsigned sent = arm_can_bus_set_send_many(&s->set, bus, frames, n);
    for (unsigned i = 0; i < sent; ++i) captured(s, bus, &frames[i]);
    s->rep->frames_tx += sent;
    s->rep->tx_dropped += n - sent;
    prof_add(s, &s->rep->prof_bus_tx_ns, c0);
}

/* Heartbeats and EMCY are sent after a period's step: they delay the next SYNC if the bus is
 * still busy with them. */
static void occupy_at_period_end(sim_t *s, int j, uint32_t id)
{
    if (s->cfg->timing != SIM_TIMING_OFF && s->rep->periods > 0u) {
        double end;
        sim_timeline_transmit(&s->timing[s->bus_of[j]], s->arm->period, &id, 1u, &end);
    }
}

static void send_heartbeat(sim_t *s, int j, int state)
{
    arm_can_frame_t f;
    sim_make_heartbeat(j, (uint8_t)(state < 0 ? s->drives[j].nmt_state : state), &f);
    send(s, (unsigned)s->bus_of[j], &f);
    occupy_at_period_end(s, j, f.id);
}

/* The arm this simulator runs, on one bus (with the boot-up and operational heartbeats): a
 * controller built for another arm refuses to start. */
static void send_identity(sim_t *s, unsigned bus)
{
    arm_can_frame_t f;
    sim_make_identity(s->arm->model_hash, s->n, &f);
    send(s, bus, &f);
}

static void send_emcys(sim_t *s, int j)
{
    sim_drive_t *d = &s->drives[j];
    for (unsigned k = 0; k < d->n_emcy_pending; ++k) {
        arm_can_frame_t f;
        sim_make_emcy(j, d->emcy_pending[k], 0x01u, &f);
        send(s, (unsigned)s->bus_of[j], &f);
        occupy_at_period_end(s, j, f.id);
        char src[24], text[96];
        snprintf(src, sizeof(src), "drive%d", j + 1);
        snprintf(text, sizeof(text), "EMCY 0x%04x: drive %d fault, torque off", d->emcy_pending[k], j + 1);
        event(s, src, "fault", text);
    }
    d->n_emcy_pending = 0u;
}

/* A frame from any bus, drives' own frames (our echoes on UDP, or another node's) counted and
 * dropped. 1 with a frame, 0 on timeout, <0 on a bus error. */
static int recv_frame(sim_t *s, arm_can_frame_t *f, unsigned *bus, double timeout_s)
{
    const int64_t end = mono_ns() + (int64_t)(timeout_s * 1e9);
    /* Poll first, then sleep: in lockstep the controller answers within tens of microseconds,
     * sooner than a sleeping process is woken on a VM. */
    const int64_t spin_ns = (int64_t)(s->cfg->spin_us * 1e3);
    const int64_t spin_end = mono_ns() + (spin_ns < (int64_t)(timeout_s * 1e9) ? spin_ns : (int64_t)(timeout_s * 1e9));
    const int64_t c_spin = prof_mark(s);
    int rc = 0;
    while (rc == 0 && spin_ns > 0 && mono_ns() < spin_end) {
        rc = arm_can_bus_set_recv(&s->set, f, bus, 0);
        if (rc == 1 && sim_is_drive_id(f->id)) {
            foreign(s, *bus, f);
            rc = 0;
        }
    }
    prof_add(s, &s->rep->prof_bus_rx_ns, c_spin);
    if (rc != 0) return rc;
    for (;;) {
        if (sim_stop_requested) return 0;
        int64_t left = end - mono_ns();
        if (left < 0) left = 0;
        const int64_t slice = left < (int64_t)(STOP_CHECK_S * 1e9) ? left : (int64_t)(STOP_CHECK_S * 1e9);
        const int64_t c0 = prof_mark(s);
        rc = arm_can_bus_set_recv(&s->set, f, bus, (int)(slice / 1000));
        prof_add(s, &s->rep->prof_bus_rx_ns, c0);
        if (rc < 0) return rc;
        if (rc == 0) {
            if (mono_ns() >= end) return 0;
            continue;
        }
        if (sim_is_drive_id(f->id)) {
            foreign(s, *bus, f);
            continue;
        }
        return 1;
    }
}

/* One bus's queued frames, now (0 when none is queued). */
static int poll_bus(sim_t *s, unsigned bus, arm_can_frame_t *f)
{
    for (;;) {
        const int rc = arm_can_bus_recv(&s->set.bus[bus], f, 0);
        if (rc != 1) return 0;
        if (sim_is_drive_id(f->id)) {
            foreign(s, bus, f);
            continue;
        }
        return 1;
    }
}

static void push_front(sim_t *s, unsigned bus, const arm_can_frame_t *f, int flag)
{
    if (s->pend_len == PENDING_MAX) { /* cannot happen (see PENDING_MAX): counted, never silent */
        s->rep->rx_pending_dropped++;
        return;
    }
    s->pend_head = (s->pend_head + PENDING_MAX - 1u) % PENDING_MAX;
    s->pending[s->pend_head] = (queued_t){.bus = bus, .f = *f, .flag = flag};
    s->pend_len++;
}

static void requeue_deferred(sim_t *s)
{
    for (unsigned k = s->n_deferred; k-- > 0u;) {
        push_front(s, s->deferred[k].bus, &s->deferred[k].f, 2);
    }
    s->n_deferred = 0u;
}

/* ---- bus timing ----------------------------------------------------------------------------- */
/* Puts this period's commands on their buses; per joint, the fraction of the period before its
 * new command took effect, or -1 if it ended after the period. */
static void emulate_commands(sim_t *s, double *effect)
{
    const double period = s->arm->period;
    const double queued = s->states_end + s->cfg->controller_latency_s;
    for (int j = 0; j < s->n; ++j) effect[j] = 0.0;
    for (unsigned b = 0; b < s->set.n; ++b) {
        uint32_t ids[SIM_MAX_JOINTS];
        int joints[SIM_MAX_JOINTS];
        unsigned k = 0;
        for (int j = 0; j < s->n; ++j) {
            if (s->bus_of[j] == (int)b && (s->got_cmd & (1u << j)) != 0u) {
                joints[k] = j;
                ids[k++] = sim_cmd_id(j);
            }
        }
        if (k == 0u) continue;
        sim_timeline_t *tl = &s->timing[b];
        double ends[SIM_MAX_JOINTS];
        sim_timeline_transmit(tl, queued, ids, k, ends);
        double last = 0.0;
        for (unsigned i = 0; i < k; ++i) last = ends[i] > last ? ends[i] : last;
        tl->stats.periods++;
        tl->stats.sync_to_last_cmd_sum_s += last;
        if (last > tl->stats.sync_to_last_cmd_max_s) tl->stats.sync_to_last_cmd_max_s = last;
        for (unsigned i = 0; i < k; ++i) {
            const int j = joints[i];
            if (ends[i] > period) {
                effect[j] = -1.0;
                if (++tl->stats.commands_late == 1u) { /* the first one says so; the count says the rest */
                    char src[24], text[200];
                    snprintf(src, sizeof(src), "bus%u", b);
                    snprintf(text, sizeof(text), "bus timing: drive %d's command ended %.3f ms after its SYNC, "
                             "after its %g ms period: not applied (bus overloaded?)", j + 1, ends[i] * 1e3,
                             period * 1e3);
                    event(s, src, "warning", text);
                }
            } else {
                effect[j] = ends[i] / period;
            }
        }
    }
}

/* ---- one period --------------------------------------------------------------------------- */
static void record_cost(sim_t *s)
{
    const int64_t now = cpu_ns();
    if (s->rep->periods > 1u) { /* the first period also carries the boot */
        const uint64_t c = (uint64_t)(now - s->cpu_mark_ns);
        const uint64_t us = c / 1000u;
        s->rep->cost_hist[us < SIM_COST_BINS ? us : SIM_COST_BINS]++;
        if (c > s->rep->cost_max_ns) s->rep->cost_max_ns = c;
        s->rep->cost_sum_ns += c;
        s->rep->cost_n++;
    }
    s->cpu_mark_ns = now;
}

/* The first thing that went wrong is the run's result; later ones do not overwrite it. */
static void set_result(sim_t *s, const char *result, const char *reason)
{
    if (strcmp(s->rep->result, "ok") == 0) {
        snprintf(s->rep->result, sizeof(s->rep->result), "%s", result);
        snprintf(s->rep->reason, sizeof(s->rep->reason), "%.390s", reason);
    }
}

/* The physics blew up (MuJoCo reset the arm to its initial state): the run's result says so,
 * once, and every drive faults with its torque off, as a drive does on a sensor fault. */
static void diverged(sim_t *s, int dof)
{
    if (strcmp(s->rep->result, "diverged") != 0) {
        char why[300];
        sim_arm_diverged_text(s->arm, dof, (unsigned long long)s->rep->periods, why, sizeof(why));
        set_result(s, "diverged", why);
        event(s, "sim", "fault", why);
    }
    for (int j = 0; j < s->n; ++j) {
        sim_drive_fault(&s->drives[j], SIM_ERR_DIVERGED, SIM_EMCY_DIVERGED);
        send_emcys(s, j);
    }
}

static void publish_truth(sim_t *s);

/* Apply the period's commands and advance the arm by one step. */
static void finish_period(sim_t *s)
{
    const int n = s->n;
    double effect[SIM_MAX_JOINTS];
    const int timed = s->cfg->timing != SIM_TIMING_OFF && !s->after_stop;
    if (timed) emulate_commands(s, effect);
    double tau[SIM_MAX_JOINTS], tau_cmd[SIM_MAX_JOINTS];
    const int ideal = sim_servo_is_ideal(&s->cfg->servo);
    for (int j = 0; j < n; ++j) {
        sim_drive_t *d = &s->drives[j];
        const double before = sim_drive_applied_torque(d);
        double held_for = 0.0; /* fraction of the period the previous torque still acts (bus timing) */
        int got = (s->got_cmd & (1u << j)) != 0u;
        if (got && timed) {
            if (effect[j] < 0.0) {
                got = 0; /* its frame ended after the period: too late for it */
                s->rep->commands_late++;
            } else {
                held_for = effect[j];
            }
        }
        if (got) sim_drive_on_command(d, s->cmd_cw[j], s->cmd_tau[j]);
        const uint8_t was_fault = d->error_code;
        sim_drive_on_period_end(d, got);
        if (d->n_emcy_pending > 0u) send_emcys(s, j);
        if (!got && was_fault == 0u && !s->after_stop) s->rep->commands_missed++;
        /* One physics step per period: a torque that changes inside it acts as its time average
         * (through the drive's latency and current loop when they are emulated). */
        tau_cmd[j] = sim_drive_period(d, sim_arm_motor_qd(s->arm, j), s->arm->period);
        sim_arm_set_brake(s->arm, j, sim_power_stage_brake_nm(&d->ps));
        if (ideal) {
            tau[j] = held_for * before + (1.0 - held_for) * tau_cmd[j];
        } else {
            tau[j] = sim_servo_period_torque(&s->cfg->servo, &s->servo[j], tau_cmd[j], held_for * s->arm->period,
                                             s->arm->period, s->arm->data->qpos[j]);
        }
    }
    memcpy(s->last_tau, tau, (size_t)n * sizeof(double));
    const int64_t c0 = prof_mark(s);
    const int bad_dof = sim_arm_step(s->arm, tau, timed ? tau_cmd : NULL, s->last_w);
    prof_add(s, &s->rep->prof_physics_ns, c0);
    if (bad_dof != 0) {
        diverged(s, bad_dof);
    }
    s->truth_pending = 1; /* published once the next period's states are out (publish_truth) */
    s->truth_faults = fault_bits(s);
    s->truth_flags = truth_flags(s);
    if (s->arm->step_count % HEARTBEAT_PERIODS == 0) {
        for (int j = 0; j < n; ++j) send_heartbeat(s, j, -1);
    }
    s->counter = -1;
    if (s->after_stop) {
        publish_truth(s);
        return;
    }
    s->rep->periods++;
    s->last_period_ns = mono_ns();
    record_cost(s);
}

/* The truth of the period just simulated (q, qd after the step, the torque applied, w). Published
 * after the next period's states have gone out, so the controller never waits for it; the
 * state it reports does not change in between (the arm moves only in finish_period). */
static void publish_truth(sim_t *s)
{
    if (!s->truth_pending) return;
    s->truth_pending = 0;
    const int64_t t1 = prof_mark(s);
    sim_telemetry_truth(s->tel, s->arm->step_count - 1, s->arm->period, s->n, s->arm->data->qpos,
                        s->arm->data->qvel, s->last_tau, s->last_w, s->truth_faults, s->truth_flags);
    prof_add(s, &s->rep->prof_telemetry_ns, t1);
}

static void sleep_until(int64_t t_ns)
{
    const struct timespec ts = {.tv_sec = t_ns / 1000000000LL, .tv_nsec = t_ns % 1000000000LL};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR && !sim_stop_requested) {
    }
}

/* TEST HOOK: the held answers go out now, after what the controller just sent. */
static void release_answers(sim_t *s)
{
    if (!s->holding_answers) return;
    s->holding_answers = 0;
    for (unsigned i = 0; i < s->n_held; ++i) send(s, s->held[i].bus, &s->held[i].f);
    s->n_held = 0u;
}

/* CANopen has one SYNC producer: on each bus the counter continues its sequence (mod 256). A SYNC
 * that does not is another master's (or a replay): every drive on that bus stops with an EMCY
 * rather than follow two masters; they still answer the period (faulted), so the controller hears why. */
static void check_sync_sequence(sim_t *s, int counter, unsigned bus)
{
    const int last = s->last_sync[bus];
    s->last_sync[bus] = counter;
    if (last < 0 || counter == ((last + 1) & 0xFF)) return;
    s->rep->rx_sync_out_of_sequence++;
    char text[160];
    snprintf(text, sizeof(text), "bus %u: SYNC counter %d after %d: a second SYNC producer (another master); the drives "
             "on this bus stop", bus, counter, last);
    event(s, "sim", "fault", text);
    for (int j = 0; j < s->n; ++j) {
        if (s->bus_of[j] == (int)bus && s->drives[j].error_code == 0u) {
            sim_drive_fault(&s->drives[j], SIM_ERR_SYNC_SEQUENCE, SIM_EMCY_PROTOCOL);
            send_emcys(s, j);
        }
    }
}

/* SYNC goes on every bus; the drives on `bus` answer on it. A period starts with its first SYNC;
 * the same counter on another bus joins it. */
static void on_sync(sim_t *s, int counter, unsigned bus)
{
    check_sync_sequence(s, counter, bus);
    if (s->counter >= 0 && (counter != s->counter || (s->synced & (1u << bus)) != 0u)) {
        finish_period(s); /* commands missing: the drives count it, the arm still moves */
    }
    if (s->counter < 0) {
        if (!sim_keeps_holding(s->cfg, s->rep->periods)) release_answers(s);
        s->holding_answers = sim_answers_late(s->cfg, s->rep->periods);
        s->counter = counter;
        s->got_cmd = 0u;
        s->synced = 0u;
        if (s->cfg->timing != SIM_TIMING_OFF) {
            s->period_wall_ns = mono_ns();
            s->states_end = 0.0;
            for (unsigned b = 0; b < s->set.n; ++b) sim_timeline_new_period(&s->timing[b], s->arm->period);
        }
    }
    s->synced |= 1u << bus;
    double send_at[SIM_MAX_JOINTS] = {0};
    if (s->cfg->timing != SIM_TIMING_OFF) { /* SYNC, then the drives' states in id order once it has ended */
        sim_timeline_t *tl = &s->timing[bus];
        const uint32_t sync_id = ARM_DRIVES_SYNC_FRAME_ID;
        double sync_end;
        sim_timeline_transmit(tl, 0.0, &sync_id, 1u, &sync_end);
        uint32_t ids[SIM_MAX_JOINTS];
        int joints[SIM_MAX_JOINTS];
        unsigned k = 0;
        for (int j = 0; j < s->n; ++j) {
            if (s->bus_of[j] == (int)bus) {
                joints[k] = j;
                ids[k++] = sim_state_id(j);
            }
        }
        double ends[SIM_MAX_JOINTS];
        sim_timeline_transmit(tl, sync_end, ids, k, ends);
        for (unsigned i = 0; i < k; ++i) {
            send_at[joints[i]] = ends[i];
            if (ends[i] > s->states_end) s->states_end = ends[i];
        }
    }
    const double *q = s->arm->data->qpos;
    const double *qd = s->arm->data->qvel;
    arm_can_frame_t batch[SIM_MAX_JOINTS];
    unsigned k = 0;
    for (int j = 0; j < s->n; ++j) {
        if (s->bus_of[j] != (int)bus) continue;
        const sim_drive_t *d = &s->drives[j];
        arm_can_frame_t *f = &batch[k++];
        double qm = q[j], qdm = qd[j], taum = sim_drive_applied_torque(d);
        if (!sim_servo_is_ideal(&s->cfg->servo)) { /* what a real drive would measure and report */
            sim_servo_measure(&s->cfg->servo, &s->servo[j], &s->noise[j], q[j], qd[j], sim_arm_motor_q(s->arm, j),
                              sim_arm_motor_qd(s->arm, j), s->arm->period, &qm, &qdm, &taum);
        }
        sim_make_state(j, qm, qdm, taum, (uint16_t)d->power, (uint8_t)counter, d->error_code, f);
        if (s->cfg->timing == SIM_TIMING_WALLCLOCK) { /* not before the frame would have ended on the bus */
            sleep_until(s->period_wall_ns + (int64_t)(send_at[j] * 1e9));
            send(s, bus, f);
            k = 0;
        }
    }
    send_batch(s, bus, batch, k); /* the bus's states in one go (one syscall on UDP) */
    publish_truth(s); /* the last period's truth, while the controller computes this one */
}

/* A SYNC on `bus` for the next period, or the run's closing NMT stop, while this period's
 * commands for drives on other buses are still missing, and the drives on `bus` have theirs. Such
 * commands may still be on their way: a socket per bus (and, on vcan, a per-CPU receive backlog)
 * does not keep the order between buses, so the next SYNC on one bus can overtake the commands on
 * another; and an NMT stop that overtook the last period's commands stopped the drives on its bus
 * before that period was applied (seen under load: the last period's truth then differed from
 * software in the loop's). Commands missing on `bus` itself are really missing (one bus keeps its
 * order). */
static int holds_back(const sim_t *s, unsigned bus, const arm_can_frame_t *f)
{
    if (s->set.n < 2u || s->counter < 0) return 0;
    if (f->id == ARM_DRIVES_NMT_FRAME_ID) {
        if (f->len != 2u || f->data[0] != SIM_NMT_STOP) return 0;
    } else if (f->len != 1u || (f->data[0] == s->counter && (s->synced & (1u << bus)) == 0u)) {
        return 0; /* a malformed SYNC, or this period's SYNC elsewhere */
    }
    int mine = 1, others = 1;
    for (int j = 0; j < s->n; ++j) {
        const int got = (s->got_cmd & (1u << j)) != 0u;
        if (s->bus_of[j] == (int)bus) mine &= got;
        else others &= got;
    }
    return mine && !others;
}

static void on_command(sim_t *s, int j, const arm_can_frame_t *f, unsigned bus)
{
    if (s->bus_of[j] != (int)bus) {
        s->rep->rx_wrong_bus++; /* not this drive's bus: a real drive never sees it */
        return;
    }
    uint16_t cw;
    double tau;
    uint8_t counter;
    if (sim_decode_cmd(f, &cw, &tau, &counter) != 0) {
        s->rep->rx_bad_frame++;
        return;
    }
    if (s->counter < 0 || counter != s->counter) {
        return; /* a command for another period: a real drive ignores it too */
    }
    if ((s->got_cmd & (1u << j)) != 0u) {
        /* Two commands for one SYNC: a second master on the bus. The drive stops and says why
         * rather than obey whichever came last. */
        s->rep->rx_duplicate_command++;
        sim_drive_fault(&s->drives[j], SIM_ERR_TWO_MASTERS, SIM_EMCY_PROTOCOL);
        send_emcys(s, j);
        return;
    }
    s->cmd_cw[j] = cw;
    s->cmd_tau[j] = tau;
    s->got_cmd |= 1u << j;
    if (s->cfg->late_answer_release == SIM_LATE_AT_COMMAND) release_answers(s);
    if (s->got_cmd == all_joints(s)) finish_period(s);
}

/* NMT goes on every bus and reaches the drives on it. Returns 0 when the controller stopped the
 * node set (the end of the run). */
static int on_nmt(sim_t *s, const arm_can_frame_t *f, unsigned bus)
{
    if (f->len != 2u) {
        s->rep->rx_bad_frame++;
        return 1;
    }
    const uint8_t command = f->data[0], node = f->data[1];
    int all_stopped = 1, changed = 0;
    for (int j = 0; j < s->n; ++j) {
        sim_drive_t *d = &s->drives[j];
        if (s->bus_of[j] == (int)bus && (node == 0u || node == d->node_id) && sim_drive_on_nmt(d, command)) {
            send_heartbeat(s, j, -1);
            changed = 1;
        }
        all_stopped &= d->nmt_state == SIM_NMT_STATE_STOPPED;
    }
    if (changed && command == SIM_NMT_START) {
        send_identity(s, bus);
    }
    return !all_stopped;
}

/* ---- main loop ---------------------------------------------------------------------------- */
static void controller_lost(sim_t *s, int booted, double timeout)
{
    char why[160];
    snprintf(why, sizeof(why), "%s for %g s: drives faulted, torque off",
             booted ? "controller silent" : "no controller on the bus", timeout);
    set_result(s, "controller-lost", why);
    s->lost = 1; /* the drives fault once the arm has run on after the stop (post_stop) */
}

/* The drives that have not faulted on their own by now: faulted (the controller was lost). */
static void fault_lost_drives(sim_t *s)
{
    for (int j = 0; j < s->n; ++j) {
        sim_drive_fault(&s->drives[j], SIM_ERR_CONTROLLER_LOST, SIM_EMCY_HEARTBEAT);
        send_emcys(s, j);
    }
}

/* After the controller stopped the drives, fell silent or the simulator was stopped: the arm runs
 * on for --post-stop s of simulated time, as fast as it computes, each drive on its own (its
 * command timeout, its fault reaction, its brake; the supply cut when the simulator was stopped
 * by a signal). Its truth goes on in ARM_SIM (SIM_FLAG_AFTER_STOP); the run's own counts stop. */
static void post_stop(sim_t *s, const char *why)
{
    if (s->counter >= 0) finish_period(s); /* the period under way: its missing commands count */
    publish_truth(s);
    double q0[SIM_MAX_JOINTS];
    const uint64_t periods = sim_after_stop_begin(s->rep, s->cfg, s->arm, s->tel, why, q0);
    s->after_stop = 1;
    if (s->power_lost) {
        for (int j = 0; j < s->n; ++j) sim_power_stage_power_lost(&s->drives[j].ps, &s->drives[j].power);
    }
    uint64_t missed[SIM_MAX_JOINTS]; /* the run's count: what the drives miss after it is not the controller's */
    for (int j = 0; j < s->n; ++j) missed[j] = s->drives[j].commands_missed;
    for (uint64_t k = 0; k < periods && strcmp(s->rep->result, "diverged") != 0; ++k) {
        s->got_cmd = 0u;
        finish_period(s);
        sim_after_stop_period(s->rep, s->arm, q0);
    }
    for (int j = 0; j < s->n; ++j) {
        s->drives[j].commands_missed = missed[j];
        sim_after_stop_drive(s->rep, j, (uint16_t)s->drives[j].power, sim_power_stage_brake_nm(&s->drives[j].ps) > 0.0);
    }
}

/* CANopen boot-up: every drive's boot-up heartbeat, and the arm this simulator runs. */
static void boot_drives(sim_t *s)
{
    for (int j = 0; j < s->n; ++j) send_heartbeat(s, j, SIM_NMT_STATE_BOOT);
    for (unsigned b = 0; b < s->set.n; ++b) send_identity(s, b);
    char text[700];
    snprintf(text, sizeof(text), "%d drives up on bus %s", s->n, s->cfg->bus_text);
    event(s, "sim", "info", text);
}

/* One frame from the controller's side of the bus. 0 once the controller stopped every drive
 * (the end of the run). */
static int on_frame(sim_t *s, const arm_can_frame_t *f, unsigned bus)
{
    sim_report_t *rep = s->rep;
    rep->frames_rx++;
    captured(s, bus, f);
    const int j = sim_cmd_joint(f->id, s->n);
    if ((f->flags & (ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_ERR | ARM_CAN_FLAG_EXT)) != 0u) {
        rep->rx_bad_frame++;
    } else if (f->id == ARM_DRIVES_SYNC_FRAME_ID) {
        if (s->first_sync_ns == 0) s->first_sync_ns = mono_ns();
        s->booted = 1;
        if (f->len != 1u) {
            rep->rx_bad_frame++;
        } else {
            on_sync(s, f->data[0], bus);
        }
    } else if (j >= 0) {
        on_command(s, j, f, bus);
    } else if (f->id == ARM_DRIVES_NMT_FRAME_ID) {
        s->booted = 1;
        return on_nmt(s, f, bus);
    } else {
        rep->rx_unknown_id++;
    }
    return 1;
}

/* The sockets' loop: frames as they come, put back in the order they were sent (sockets keep no
 * order between buses), until the controller stops the drives or falls silent. */
static void run_loop(sim_t *s)
{
    const sim_config_t *cfg = s->cfg;
    char text[700];
    const uint32_t sync_id = ARM_DRIVES_SYNC_FRAME_ID, nmt_id = ARM_DRIVES_NMT_FRAME_ID;
    for (;;) {
        const double timeout = s->booted ? cfg->idle_timeout_s : cfg->boot_timeout_s;
        if (s->n_deferred > 0u && (s->counter < 0 || s->n_deferred >= s->set.n)) requeue_deferred(s);
        int flag = 0, have = 0;
        unsigned bus = 0;
        arm_can_frame_t f;
        if (s->pend_len > 0u) {
            const queued_t *q = &s->pending[s->pend_head];
            bus = q->bus;
            f = q->f;
            flag = q->flag;
            s->pend_head = (s->pend_head + 1u) % PENDING_MAX;
            s->pend_len--;
            have = 1;
        } else {
            const double defer_s = cfg->reorder_wait_s;
            const int rc = recv_frame(s, &f, &bus, s->n_deferred > 0u && defer_s < timeout ? defer_s : timeout);
            if (rc < 0) {
                snprintf(text, sizeof(text), "receiving on bus %u failed: %s", bus, strerror(errno));
                set_result(s, "bus-error", text);
                break;
            }
            if (sim_stop_requested) {
                snprintf(text, sizeof(text), "stopped by a signal after %llu periods", (unsigned long long)s->rep->periods);
                set_result(s, "interrupted", text);
                s->power_lost = 1;
                break;
            }
            if (rc == 0 && s->n_deferred > 0u) { /* the missing commands never came */
                requeue_deferred(s);
                continue;
            }
            have = rc == 1;
        }
        if (have && s->set.n > 1u && flag == 0 && (f.id == sync_id || f.id == nmt_id)) {
            /* SYNC and NMT go on every bus. Order between buses is lost in the sockets: what is
             * already queued on the other buses was sent before this frame (e.g. the previous
             * period's commands), so it is handled first. */
            queued_t earlier[EARLIER_MAX]; /* bounded: a flood beyond it waits in the socket */
            unsigned k = 0;
            for (unsigned i = 0; i < s->set.n && k < EARLIER_MAX; ++i) {
                if (i == bus) continue;
                while (k < EARLIER_MAX && poll_bus(s, i, &earlier[k].f)) {
                    earlier[k].bus = i;
                    earlier[k++].flag = 1;
                }
            }
            if (k > 0u) {
                push_front(s, bus, &f, 1);
                for (unsigned i = k; i-- > 0u;) push_front(s, earlier[i].bus, &earlier[i].f, 1);
                continue;
            }
        }
        if (have && flag != 2 && (f.id == sync_id || f.id == nmt_id) && holds_back(s, bus, &f)) {
            int already = 0;
            for (unsigned i = 0; i < s->n_deferred; ++i) already |= s->deferred[i].bus == bus;
            if (!already) {
                s->deferred[s->n_deferred++] = (queued_t){.bus = bus, .f = f, .flag = 1};
                continue;
            }
        }
        if (!have) {
            controller_lost(s, s->booted, timeout);
            break;
        }
        if (!on_frame(s, &f, bus)) {
            s->ended = 1; /* the controller stopped every drive, as sim_service records it */
            break;
        }
    }
}

/* The end of the run: the last truth, the report's totals, and why it ended. */
static void wrap_up(sim_t *s)
{
    sim_report_t *rep = s->rep;
    for (int k = 0; k < s->n; ++k) { /* the run's drive faults: those of the stop (post_stop's are its own) */
        if (s->drives[k].error_code != 0u) rep->drive_fault_mask |= 1u << k;
    }
    if (s->cfg->post_stop_s > 0.0 && s->booted && strcmp(rep->result, "diverged") != 0) {
        post_stop(s, s->power_lost ? "the simulator was stopped: the drives lost their supply"
                     : s->lost     ? "the controller fell silent"
                     : s->ended    ? "the controller stopped the drives (NMT stop)"
                                   : "the bus failed");
    }
    if (s->lost) { /* the controller was lost: every drive faulted, on its own or now */
        fault_lost_drives(s);
        for (int k = 0; k < s->n; ++k) rep->drive_fault_mask |= 1u << k;
    }
    publish_truth(s);
    const int64_t t_end = mono_ns();
    rep->wall_s = (double)(t_end - s->t0_ns) * 1e-9;
    if (s->first_sync_ns > 0) {
        rep->boot_s = (double)(s->first_sync_ns - s->t0_ns) * 1e-9;
        rep->run_wall_s = (double)(s->last_period_ns - s->first_sync_ns) * 1e-9;
    }
    for (int k = 0; k < s->n; ++k) rep->commands_missed_per_drive[k] = s->drives[k].commands_missed;
    for (unsigned b = 0; b < s->set.n; ++b) {
        rep->rx_undecodable += arm_can_bus_rx_undecodable(&s->set.bus[b]);
        rep->rx_kernel_drops += arm_can_bus_rx_kernel_drops(&s->set.bus[b]);
    }
    char text[700];
    if (rep->reason[0] != '\0') {
        event(s, "sim", "fault", rep->reason);
    } else {
        snprintf(text, sizeof(text), "stopped by the controller after %llu periods", (unsigned long long)rep->periods);
        event(s, "sim", "info", text);
    }
    rep->n_buses = s->set.n;
    for (unsigned b = 0; b < s->set.n; ++b) rep->bus_stats[b] = s->timing[b].stats;
    arm_can_bus_set_close(&s->set);
}

sim_t *sim_begin(const sim_config_t *cfg, sim_arm_t *arm, sim_telemetry_t *tel, sim_report_t *rep, char *err,
                 unsigned long errcap)
{
    static sim_t s;
    memset(&s, 0, sizeof(s));
    memset(rep, 0, sizeof(*rep));
    snprintf(rep->result, sizeof(rep->result), "ok");
    s.cfg = cfg;
    s.arm = arm;
    s.tel = tel;
    s.rep = rep;
    s.n = arm->n;
    s.counter = -1;
    for (unsigned b = 0; b < ARM_CAN_BUS_SET_MAX; ++b) s.last_sync[b] = -1;
    for (int j = 0; j < s.n; ++j) {
        s.bus_of[j] = arm_can_bus_set_bus_of(&cfg->buses, (unsigned)j);
        if (s.bus_of[j] < 0) {
            snprintf(err, errcap, "--bus: drive %d is on no bus", j + 1);
            return NULL;
        }
        sim_drive_init(&s.drives[j], (uint8_t)(j + 1), arm->torque_limit[j], cfg->command_timeout_periods);
        sim_drive_set_stopping(&s.drives[j], &cfg->brake[j], arm->drive_inertia[j], cfg->quick_stop_decel);
        if (cfg->brakes_released_at_start) sim_power_stage_release_brake(&s.drives[j].ps);
        sim_arm_set_brake(arm, j, sim_power_stage_brake_nm(&s.drives[j].ps));
        sim_servo_init(&s.servo[j]);
        /* not the uncertainty's stream, and one per drive */
        sim_rng_seed(&s.noise[j], arm->unc.seed ^ (0x9E3779B97F4A7C15ull * ((uint64_t)j + 1u)));
    }
    memcpy(s.timing, cfg->timelines, sizeof(s.timing));
    if (arm_can_bus_set_open(&s.set, &cfg->buses, err, errcap) != 0) {
        return NULL;
    }
    s.cpu_mark_ns = cpu_ns();
    s.t0_ns = mono_ns();
    boot_drives(&s);
    return &s;
}

int sim_service(sim_t *s)
{
    arm_can_frame_t f;
    unsigned bus = 0;
    while (!s->ended && arm_can_bus_set_recv(&s->set, &f, &bus, 0) == 1) {
        if (sim_is_drive_id(f.id)) {
            foreign(s, bus, &f);
            continue;
        }
        s->ended = !on_frame(s, &f, bus);
    }
    return !s->ended;
}

void sim_end(sim_t *s)
{
    wrap_up(s);
}

int sim_run(const sim_config_t *cfg, sim_arm_t *arm, sim_telemetry_t *tel, sim_report_t *rep, char *err,
            unsigned long errcap)
{
    sim_t *s = sim_begin(cfg, arm, tel, rep, err, errcap);
    if (s == NULL) {
        return -1;
    }
    run_loop(s);
    wrap_up(s);
    return 0;
}
