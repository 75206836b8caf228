/* The controller process: boot the drives, run the periodic loop, stop safely. */
#ifndef ARM_CONTROLLER_LOOP_H
#define ARM_CONTROLLER_LOOP_H

#include <stdint.h>

#include "arm/drive_bus.h"
#include "arm_params.h"
#include "options.h"
#include "task.h"
#include "telemetry.h"

/* arm_controller's exit codes: the registry's (controller-exit, firmware/params/params.toml), which
 * tools/run/verdict.py reads too. */
typedef enum {
    RUN_OK = ARM_P_CONTROLLER_EXIT_OK,
    RUN_BUS_ERROR = ARM_P_CONTROLLER_EXIT_BUS_ERROR,     /* could not open or use the bus */
    RUN_BOOT_FAILED = ARM_P_CONTROLLER_EXIT_BOOT_FAILED, /* a drive did not come up */
    RUN_FAULT = ARM_P_CONTROLLER_EXIT_FAULT,             /* runtime fault: safe stop was commanded */
    RUN_INTERRUPTED = ARM_P_CONTROLLER_EXIT_INTERRUPTED, /* SIGTERM, SIGINT or SIGHUP: safe stop was commanded */
} run_result_t;

#include <signal.h>
/* The signal that asked the loop to stop (0: none); set by main's handler. */
extern volatile sig_atomic_t controller_stop_signal;

/* The boot's SDO writes a run's report keeps: every bus's whole log, except on the MCU, whose
 * report leaves in one frame of 8 KiB (cortex_m/telemetry_mcu.c: about 800 writes fit) and whose
 * 128 KiB part has no RAM to spare for writes that frame could not carry. */
#ifdef ARM_PORT_MCU
#define ARM_REPORT_CO_WRITES_MAX 512u
#else
#define ARM_REPORT_CO_WRITES_MAX (ARM_CAN_BUS_SET_MAX * ARM_CO_BOOT_LOG_MAX)
#endif

/* What began a stop (controller_loop.c controlled_stop: the one path every stop takes). */
typedef enum { RUN_STOP_NONE = 0, RUN_STOP_END, RUN_STOP_FAULT, RUN_STOP_SIGNAL } run_stop_cause_t;

/* How the arm was stopped: the safe state it reached (summary.json "stop", ARM_EVENT). */
typedef struct {
    run_stop_cause_t cause;            /* NONE: never enabled, nothing to stop */
    uint32_t from_bus_period;          /* the stop's first period */
    uint32_t periods;                  /* its periods, up to the NMT stop */
    uint32_t quick_stop_periods;       /* of them, the drives' quick stop */
    uint32_t stopped_mask;             /* drives that reported switch on disabled or fault */
    int braked;                        /* every drive did: braked and disabled */
    char safe_state[240];
    uint16_t statusword[ARM_N_JOINTS]; /* each drive's last */
} run_stop_t;

typedef struct {
    run_result_t result;
    char reason[512];
    uint32_t steps_done;
    uint32_t bus_periods; /* SYNCs sent (boot and enable periods included) */
    uint64_t frames_tx;
    uint64_t frames_rx;
    uint64_t tx_would_block;
    uint64_t rx_wrong_bus; /* a drive's frame (STATE/HEARTBEAT/EMCY) on a bus that is not its own */
    uint64_t rx_undecodable; /* datagrams / frames the transport could not decode (its count) */
    uint64_t rx_kernel_drops; /* frames the kernel dropped on a full receive queue (SO_RXQ_OVFL) */
    uint64_t overruns;
    double wall_s;
    double boot_s;
    arm_state_t final_state;
    arm_fault_t final_fault;
    arm_rx_counters_t rx;
    /* --protocol canopen: the boot's SDO writes (every bus, in order), its first fault, its time */
    int canopen;
    double co_boot_s;
    arm_co_fault_t co_fault;
    unsigned n_co_writes;
    arm_co_write_t co_writes[ARM_REPORT_CO_WRITES_MAX];
    arm_co_drive_units_t co_units[ARM_N_JOINTS]; /* each joint's drive's units, as the boot settled them */
    float co_q_first[ARM_N_JOINTS];              /* each joint's first position decoded with them, rad */
    unsigned co_q_seen;                          /* bit j: joint j's first position came */
    task_report_t task;                          /* what the task did (task.h) */
    run_stop_t stop;
    /* Periods whose states missed the wait, by the side that was late (lateness.h: none, the plant,
     * the controller, the bus), the worst of each (us); a stop for lateness: its side and why. */
    uint32_t late_count[4];
    int32_t late_worst_us[4];
    int late_side;
    char late_text[300];
} run_report_t;

void controller_run(const options_t *opt, const arm_robot_model_t *model, telemetry_t *telem,
                    run_report_t *report);

#endif
