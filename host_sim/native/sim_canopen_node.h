/* One emulated drive as a CANopen CiA 402 slave, its objects those of an EDS or DCF (the build's
 * own firmware/protocol/cia402_servo.eds, or any drive's file: arm_sim --od): NMT, an SDO server,
 * heartbeat producer (0x1017) and consumer (0x1016) where the file has them, SYNC-driven PDOs that
 * follow their communication and mapping objects and the file's mapping rules (which objects, in
 * which direction, how many), EMCY, and the CiA 402 power state machine. No I/O: the loop
 * (sim_canopen_loop.c) hands it frames, SYNCs and the time, and sends what it queues in `out`. */
#ifndef ARM_SIM_CANOPEN_NODE_H
#define ARM_SIM_CANOPEN_NODE_H

#include <stdint.h>

#include "arm/can_frame.h"
#include "sim_canopen_od.h"
#include "sim_canopen_sdo.h"
#include "sim_cia402.h"
#include "sim_drive.h"

#define SIM_CO_N_PDO 4u     /* RPDO1..4, TPDO1..4 (those the file has) */
#define SIM_CO_MAP_MAX 8u   /* entries per mapping */
#define SIM_CO_OUT_MAX 16u  /* frames queued between two flushes */

#define SIM_CO_EMCY_OVERCURRENT 0x2310u /* CiA 402: continuous overcurrent */
#define SIM_CO_EMCY_HEARTBEAT 0x8130u   /* CiA 301: life guard / heartbeat error */
#define SIM_CO_EMCY_RESET 0x0000u       /* CiA 301: error reset / no error */

typedef struct {
    uint32_t cob_id;
    int valid;
    uint8_t trans;
    unsigned n;
    uint16_t index[SIM_CO_MAP_MAX];
    uint8_t sub[SIM_CO_MAP_MAX];
    uint8_t bytes[SIM_CO_MAP_MAX];
    unsigned len; /* frame bytes */
} sim_co_pdo_t;

typedef struct {
    uint8_t id;
    uint8_t nmt; /* SIM_NMT_STATE_* */
    sim_co_od_t od;
    sim_co_sdo_t sdo;
    const sim_co_table_t *table; /* the drive's file */
    sim_co_preset_t preset;
    double limit_nm;            /* the joint's torque limit: the drive gives no more */
    sim_power_t power;
    sim_power_stage_t ps;       /* brake, quick stop (0x605A, 0x6084, 0x6085), fault reaction (0x605E) */
    sim_brake_config_t brake;   /* the drive table's (arm_sim --brake) */
    double joint_inertia;       /* what its velocity loop is tuned for */
    double default_decel;       /* rad/s^2: a ramp's deceleration when the drive lacks 0x6084/0x6085 */
    uint16_t prev_cw;
    sim_co_pdo_t rpdo[SIM_CO_N_PDO], tpdo[SIM_CO_N_PDO];
    uint8_t rpdo_data[SIM_CO_N_PDO][8];
    int rpdo_pending[SIM_CO_N_PDO]; /* synchronous RPDO received: applied at the next SYNC */
    unsigned tpdo_syncs[SIM_CO_N_PDO];
    int64_t hb_next_ns;         /* heartbeat producer */
    int64_t hbc_last_ns;        /* heartbeat consumer: the producer's last heartbeat */
    int hbc_armed;              /* monitoring runs from the producer's first heartbeat on */
    double overcurrent_at_s;    /* TEST HOOK: < 0 off */
    int overcurrent_done;
    int64_t now_ns;             /* the time of the frame or tick being handled */
    uint64_t pdo_rx, pdo_rx_short, emcy_sent;
    arm_can_frame_t out[SIM_CO_OUT_MAX];
    unsigned n_out;
    uint64_t out_dropped;
} sim_co_node_t;

/* -1 with one line if the drive has no units (no 0x608F, 0x6091 or 0x6076 and no preset of it). */
int sim_co_node_init(sim_co_node_t *n, const sim_co_table_t *table, uint8_t id, const sim_co_preset_t *preset,
                     double limit_nm, double overcurrent_at_s, char *err, unsigned long errcap);
/* Power-on or NMT reset node: every object to its default, boot-up heartbeat, pre-operational. */
void sim_co_node_boot(sim_co_node_t *n, int64_t now_ns);
/* 1 for a COB-ID this node sends (its own frames, heard back on a UDP bus). */
int sim_co_node_sends(const sim_co_node_t *n, uint32_t id);
/* NMT, SDO requests, RPDOs, the monitored heartbeat; SYNC is sim_co_node_on_sync. */
void sim_co_node_on_frame(sim_co_node_t *n, const arm_can_frame_t *f, int64_t now_ns);
/* SYNC: synchronous RPDOs take effect, the actual values (joint q, qd, and the torque measured,
 * NaN: the torque applied) are sampled and the synchronous TPDOs go out. */
void sim_co_node_on_sync(sim_co_node_t *n, double q, double qd, double tau_measured);
/* Timers: heartbeat producer and consumer; the overcurrent test hook at simulated time sim_s. */
void sim_co_node_tick(sim_co_node_t *n, int64_t now_ns, double sim_s);
/* Longest the loop may wait before calling tick again (ns from now_ns). */
int64_t sim_co_node_wait_ns(const sim_co_node_t *n, int64_t now_ns);
/* Its stopping (sim_power_stage.h): its brake, the joint's inertia, and the deceleration of a ramp
 * when its file has no 0x6084/0x6085 (rad/s^2 at the joint). Before sim_co_node_boot. */
void sim_co_node_set_stopping(sim_co_node_t *n, const sim_brake_config_t *brake, double joint_inertia,
                              double default_decel);
/* The torque the drive is told to apply: the target torque in CST, NMT operational (what operation
 * enabled applies). */
double sim_co_node_torque(const sim_co_node_t *n);
/* One period of dt s of its power stage at joint velocity qd: the torque it applies. */
double sim_co_node_period(sim_co_node_t *n, double qd, double dt);
/* Power lost (the simulator stopped by a signal): no torque, its brake closes on its own. */
void sim_co_node_power_lost(sim_co_node_t *n);
void sim_co_node_fault(sim_co_node_t *n, uint16_t emcy_code, uint8_t error_register);
/* SDO access as the server uses it (exposed for the C tests). */
uint32_t sim_co_node_read(void *node, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap, unsigned *len);
uint32_t sim_co_node_write(void *node, uint16_t index, uint8_t sub, const uint8_t *data, unsigned len);
uint32_t sim_co_node_exists(void *node, uint16_t index, uint8_t sub);

#endif
