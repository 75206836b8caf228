/* The simulator's run: n emulated drives on the CAN bus(es), the arm advancing one period per
 * controller SYNC once every drive's command for it is in (lockstep), or as the commands come
 * (realtime: the controller's clock sets the pace). Ends when the controller stops every drive
 * (NMT stop), or faults the drives when the controller falls silent. */
#ifndef ARM_SIM_LOOP_H
#define ARM_SIM_LOOP_H

#include <signal.h>
#include <stdint.h>

#include "arm/can_bus.h"
#include "sim_arm.h"
#include "sim_bus_timing.h"
#include "sim_capture.h"
#include "sim_power_stage.h"
#include "sim_servo.h"
#include "sim_telemetry.h"

typedef enum { SIM_TIMING_OFF = 0, SIM_TIMING_VIRTUAL, SIM_TIMING_WALLCLOCK } sim_timing_mode_t;

/* TEST HOOK (--debug-late-answer PERIOD[-LAST]:WHEN): the drives' answers to those periods' SYNCs
 * are held back until the controller has stopped waiting for them, told by what it sends next
 * rather than by a time, which a loaded machine would blur: its first command of the period (it has
 * taken the period as stale, and the next SYNC has not gone out yet) or its next SYNC. */
/* TEST HOOK: when answers held back go out: at the controller's command of their period, at the
 * next SYNC, or all of them together at the SYNC after the last late period (a plant that stalled
 * for several periods, then caught up). */
typedef enum { SIM_LATE_AT_COMMAND = 0, SIM_LATE_AT_NEXT_SYNC, SIM_LATE_IN_ONE_BURST } sim_late_release_t;
#define SIM_LATE_BURST_MAX 3u /* periods one burst holds (the drives' queues hold that many answers) */

typedef struct {
    arm_can_bus_set_config_t buses;
    char bus_text[600];          /* the --bus arguments as given, for messages */
    double boot_timeout_s;       /* wait this long for the controller's first frame */
    double idle_timeout_s;       /* then this long of silence faults the drives */
    uint32_t command_timeout_periods;
    sim_timing_mode_t timing;
    double controller_latency_s; /* bus timing: last state frame in -> commands queued */
    sim_timeline_t timelines[ARM_CAN_BUS_SET_MAX]; /* bus timing: one per bus, frame times set */
    int profile;                 /* break each period's CPU time down by activity */
    double spin_us;              /* poll the bus this long before sleeping on it */
    /* Longest a next-period SYNC on one bus is held back while this period's commands for drives on
     * another bus are missing (they may still be on their way: sockets per bus keep no order
     * between buses). Long in lockstep (nothing is timed); a fraction of a period in realtime,
     * where holding a SYNC back is what makes the controller's states late. */
    double reorder_wait_s;
    sim_servo_config_t servo;    /* the drives' sensing and torque path (all zero: ideal drives) */
    sim_capture_t *capture;      /* every frame received or sent, candump's log format (NULL: none) */
    int lose_bus;                /* TEST HOOK: this bus sends nothing from period lose_bus_from on; -1: off */
    uint64_t lose_bus_from;
    int64_t late_answer_period;  /* TEST HOOK: the drives answer the SYNCs of these periods late; -1: off */
    int64_t late_answer_last;
    sim_late_release_t late_answer_release;
    /* The drives' stopping (sim_power_stage.h): each joint's brake (--brake), the deceleration of
     * a drive's ramp where it has no 0x6084/0x6085 (the arm protocol's drives always), and how long
     * the arm is simulated on after the controller stopped the drives or fell silent (--post-stop). */
    sim_brake_config_t brake[SIM_MAX_JOINTS];
    int brakes_released_at_start; /* --brakes-at-start released */
    double quick_stop_decel;
    double post_stop_s;
} sim_config_t;

/* TEST HOOK: whether the drives answer bus period `period`'s SYNC late (sim_late_release_t). */
static inline int sim_answers_late(const sim_config_t *cfg, uint64_t period)
{
    return cfg->late_answer_period >= 0 && period >= (uint64_t)cfg->late_answer_period &&
           period <= (uint64_t)cfg->late_answer_last;
}

/* TEST HOOK: whether what is held stays held at the SYNC of `period` (a burst still gathering). */
static inline int sim_keeps_holding(const sim_config_t *cfg, uint64_t period)
{
    return cfg->late_answer_release == SIM_LATE_IN_ONE_BURST && sim_answers_late(cfg, period);
}

/* ARM_SIM's flags: bit j, joint j's brake holds; this bit, the period is after the stop. */
#define SIM_FLAG_AFTER_STOP (1 << 16)

#define SIM_COST_BINS 5000u /* per-period CPU cost histogram, 1 us bins */
#define SIM_ANSWER_LAST 1536u /* the last periods whose answer times the summary keeps: a stop's and those before it */

typedef struct {
    char result[32]; /* "ok", "controller-lost", "bus-error", "interrupted" */
    char reason[400];
    uint64_t periods;
    uint64_t frames_tx;
    uint64_t frames_rx;
    uint64_t tx_dropped;
    uint64_t rx_foreign_drive; /* a frame only drives send (STATE, HEARTBEAT, EMCY), from another node */
    uint64_t rx_unknown_id;
    uint64_t rx_bad_frame;
    uint64_t rx_pending_dropped; /* frames read but lost on a full reorder ring (0 by construction) */
    uint64_t rx_undecodable; /* UDP datagrams that are not python-can frames, SocketCAN frames that do not decode */
    uint64_t rx_kernel_drops; /* frames the kernel dropped on a full receive queue (SO_RXQ_OVFL) */
    uint64_t rx_wrong_bus;   /* a command for a drive that is not on the bus it arrived on */
    uint64_t rx_duplicate_command; /* a second command for one drive and SYNC: the drive faults */
    uint64_t rx_sync_out_of_sequence; /* a SYNC counter that does not continue its bus's sequence */
    uint64_t commands_missed;
    uint64_t commands_late;  /* bus timing: the command's frame ended after its period */
    uint64_t commands_missed_per_drive[SIM_MAX_JOINTS];
    uint32_t drive_fault_mask;
    unsigned n_buses;
    sim_bus_stats_t bus_stats[ARM_CAN_BUS_SET_MAX]; /* bus timing, per bus */
    double wall_s;
    double boot_s;           /* start -> the controller's first SYNC */
    double run_wall_s;       /* first SYNC -> last period */
    uint64_t cost_hist[SIM_COST_BINS + 1u]; /* per-period thread CPU time, us; last bin: more */
    uint64_t cost_max_ns;
    uint64_t cost_sum_ns;
    uint64_t cost_n;
    /* --profile: thread CPU time per activity, summed over the periods measured */
    uint64_t prof_physics_ns, prof_bus_tx_ns, prof_bus_rx_ns, prof_telemetry_ns;
    /* After the stop (--post-stop): why it began, its first step, the periods simulated, each
     * joint's largest motion in them, and what the drives ended in (their state, their brake). */
    char post_stop_why[160];
    int64_t post_stop_from_step;
    double post_stop_mujoco_s;      /* MuJoCo's clock when it began */
    uint64_t post_stop_periods;
    double post_stop_moved_rad[SIM_MAX_JOINTS];
    uint16_t post_stop_statusword[SIM_MAX_JOINTS];
    uint32_t post_stop_braked_mask; /* bit j: joint j's brake engaged at the end */
    /* How fast the drives answered each SYNC (where the bus says when the master sent it: UDP): the
     * simulator's reading of the SYNC and its answers' leaving, after the SYNC was sent, us
     * (histograms of 1 us bins, the last bin: more), and the last periods' of them. */
    uint64_t read_hist[SIM_COST_BINS + 1u], answer_hist[SIM_COST_BINS + 1u];
    uint64_t answer_n;
    double read_max_us, answer_max_us;
    int64_t answer_last[SIM_ANSWER_LAST][3]; /* bus period, read us, answered us */
    unsigned answer_last_n;
} sim_report_t;

/* Set from a signal handler: the loop stops at its next frame or within 100 ms. */
extern volatile sig_atomic_t sim_stop_requested;

typedef struct sim sim_t;

/* Runs until the controller stops the drives, falls silent, or a stop is requested. Returns 0
 * when the run could start (the report says how it ended), -1 with err if the buses could not be
 * opened. */
int sim_run(const sim_config_t *cfg, sim_arm_t *arm, sim_telemetry_t *tel, sim_report_t *rep, char *err,
            unsigned long errcap);

/* The same run as steps, for a software-in-the-loop runner that calls the controller and the
 * drives in turn in one thread (the buses in-process, mem:K): sim_begin opens the buses and boots
 * the drives (NULL with err if the buses could not be opened); sim_service handles every frame
 * queued for the drives, never waiting, and returns 0 once the controller stopped them; sim_end
 * writes the report's totals and closes the buses. */
sim_t *sim_begin(const sim_config_t *cfg, sim_arm_t *arm, sim_telemetry_t *tel, sim_report_t *rep, char *err,
                 unsigned long errcap);
int sim_service(sim_t *s);
void sim_end(sim_t *s);

#endif
