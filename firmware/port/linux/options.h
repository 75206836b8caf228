/* Command-line options of the Linux controller binary. */
#ifndef ARM_OPTIONS_H
#define ARM_OPTIONS_H

#include <stdint.h>

#include "arm/can_bus_config.h"
#include "arm/co_boot.h"
#include "arm/controller.h"
#include "arm/reference.h"
#include "design_file.h"
#include "rt.h"

typedef enum { MODE_LOCKSTEP = 0, MODE_REALTIME } run_mode_t;

typedef struct {
    char bus[600];          /* the --bus arguments as given, space-separated (for messages) */
    arm_can_bus_set_config_t buses; /* --bus SPEC[@DRIVES], repeatable; default: one udp bus */
    char lcm_url[256];      /* "" = no telemetry */
    char summary_path[512]; /* "" = none */
    run_mode_t mode;
    double duration_s;
    uint32_t steps;          /* derived from duration and rate */
    double rate_hz;
    double boot_timeout_s;
    double lockstep_timeout_s; /* lockstep: wall time to wait for a period's states */
    double stop_timeout_s;     /* --stop-timeout: how long a stop waits for the drives' quick stop */
    double spin_us;            /* poll this long for a frame before sleeping in ppoll */
    int protocol_canopen;      /* --protocol canopen: CiA 301/402 drives (docs/drives.md) */
    /* --node, one per joint in joint order (gen/drives.py's table of the arm); n_nodes 0: the
     * built-in rule (node = drive number, rated torque = the joint's torque limit, EDS encoder/gear) */
    unsigned n_nodes;
    uint8_t rpdo_type;         /* --rpdo-type: RPDO1's transmission type [1] */
    uint8_t tpdo2_type;        /* --tpdo2-type: TPDO2's, every N-th SYNC [1] */
    /* --heartbeat-ms, --consumer-ms, --master-id: the drive table's heartbeat_ms, consumer_ms and
     * master_id (0x1017, 0x1016.1, the master's own heartbeat) */
    uint32_t co_heartbeat_ms;
    uint32_t co_consumer_ms;
    uint32_t co_master_id;
    arm_co_node_config_t node[ARM_N_JOINTS];
    arm_ctl_config_t ctl;
    double position_margin_rad; /* --position-margin: ctl's q_min, q_max are the model's widened by it */
    double torque_mismatch;     /* --torque-mismatch: ctl's limits, a fraction of each torque limit */
    design_file_t design; /* --design-file: ctl.design points here; else the built-in design */
    rt_options_t rt; /* --rt-priority, --cpu (rt.h) */
    double ref_hold_s;               /* --ref-hold: settle on the start pose first */
    int ref_given;                   /* 1: --ref-amp/--ref-freq replace the default reference */
    float ref_amp[ARM_N_JOINTS];     /* rad */
    float ref_freq_hz[ARM_N_JOINTS]; /* Hz */
    /* the task (task.h): what the arm does once the drives are enabled */
    int task;                        /* --task: task_kind_t */
    int reference_home;              /* --reference-origin home: the reference around home, after a move there */
    double move_speed, move_accel;   /* the bounded move to a task's first point, rad/s and rad/s^2 */
    int jog_joint;                   /* --jog J:RAD: 0-based joint (-1: none given) */
    float jog_rad;
    double jog_speed;
    double end_hold_s;
    double brake_release_s;          /* the drives' brakes open this long after enable: a task waits */
    char trajectory_path[512];       /* --trajectory (loaded at parse time: traj_file.h) */
    arm_traj_t trajectory;
    char stream_url[256];
    double stream_timeout_s;
    float commission_pulse[ARM_N_JOINTS]; /* N m; 0: 5 % of the joint's torque limit */
} options_t;

/* Parses argv into opt (starting from the defaults). On a bad argument writes a message naming
 * the option and value into err and returns -1; returns 1 if --help was printed, 0 otherwise. */
int options_parse(int argc, char **argv, const arm_robot_model_t *model, options_t *opt, char *err,
                  unsigned long errcap);
void options_usage(const char *prog);

#endif
