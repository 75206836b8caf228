/* arm_sim --protocol canopen: the emulated drives as CANopen CiA 402 slaves (sim_canopen_node.c)
 * for an external master, in realtime: the arm advances when the master's SYNC comes (0x1006's
 * cycle period of simulated time per SYNC, at least one period), as the firmware's own protocol
 * does in realtime runs. Node id = drive number; SYNC on the first joint's bus moves the arm. */
#ifndef ARM_SIM_CANOPEN_LOOP_H
#define ARM_SIM_CANOPEN_LOOP_H

#include "sim_canopen_node.h"
#include "sim_loop.h"
#include "sim_plant.h"

typedef enum { SIM_PROTOCOL_ARM = 0, SIM_PROTOCOL_CANOPEN } sim_protocol_t;

typedef struct {
    const sim_co_table_t *table; /* --od: the drives' file as gen/eds.py's table (NULL: the build's own) */
    sim_co_preset_t preset;  /* every node's: the options' (0: the file's) */
    /* --node: node i + 1's own, the arm's drive table (gen/drives.py), over `preset` (0: preset's) */
    sim_co_preset_t node_preset[SIM_MAX_JOINTS];
    int overcurrent_node;    /* TEST HOOK: this node trips 0x2310 (0: none) */
    double overcurrent_at_s; /* at this simulated time, once operation is enabled */
    sim_plant_t *plant;      /* the truth, brakes and sessions (sim_plant.h; NULL: none) */
    int serve;               /* --serve: masters come and go; the run ends on a signal (sim_plant.h) */
    const char *sessions_path; /* --serve: each session's record, rewritten as it changes ("": none) */
} sim_co_config_t;

typedef struct co_sim co_sim_t;

int sim_canopen_run(const sim_config_t *cfg, const sim_co_config_t *co, sim_arm_t *arm, sim_telemetry_t *tel,
                    sim_report_t *rep, char *err, unsigned long errcap);

/* The same run as steps, for the software-in-the-loop runner (arm_sil), as sim_loop.h's
 * sim_begin/sim_service/sim_end: service handles every frame queued, then the nodes' timers; 0
 * once the master has stopped every drive. */
co_sim_t *sim_co_begin(const sim_config_t *cfg, const sim_co_config_t *co, sim_arm_t *arm, sim_telemetry_t *tel,
                       sim_report_t *rep, char *err, unsigned long errcap);
int sim_co_service(co_sim_t *s);
void sim_co_end(co_sim_t *s);

#endif
