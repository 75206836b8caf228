/* The CiA 402 boot configurator: brings every node of one bus from power-on to operation enabled
 * in cyclic synchronous torque mode (docs/drives-bring-up.md). Non-blocking: the port calls
 * arm_co_boot_rx for every received frame and arm_co_boot_step once per period, and sends the
 * frames arm_co_boot_take_tx hands it. The nodes boot side by side (each has its own SDO channel).
 * No heap, no I/O.
 *
 * Per node, in order: NMT pre-operational; upload 0x1000 (its low word must be the CiA 402 profile,
 * 0x0192) and 0x1018.1-4 (vendor and product checked when the configuration names them); the
 * units, read from the drive and never written: 0x6502 (bit 9, CST, must be set), 0x6076 the
 * motor's rated torque, 0x608F.1-2 encoder, 0x6091.1-2 gear, 0x6072 max torque; where the
 * configuration gives one of them the drive's must equal it, and where the drive lacks one (CiA 402
 * makes 0x608F, 0x6091 and 0x6072 optional) the configuration's stands in (ARM_CO_FAULT_UNITS_*
 * otherwise); the joint's torque limit, where the configuration gives it, must be within what the
 * drive gives at the joint, 0x6072 x 0x6076 x gear x efficiency (ARM_CO_FAULT_TORQUE_LIMIT);
 * the statusword, and controlword 0x00 if the drive is not switch on disabled (a drive left
 * enabled takes no new mode); for RPDO1, TPDO1, TPDO2: COB-ID invalid (bit 31), mapping count 0,
 * entries, count, transmission type, COB-ID valid; 0x1006 cycle period, 0x1017 heartbeat, each
 * written only if the drive has it (CiA 301 makes them optional: an abort 0x06020000 or 0x06090011
 * skips it); 0x1016.1 consumer heartbeat of the master, the drive's watchdog on the master: a drive
 * that has none or refuses it is refused (ARM_CO_FAULT_NO_WATCHDOG: a dead master would leave it
 * applying its last torque), unless the configuration accepts that; how the drive stops (CiA 402:
 * quick stop option 0x605A = 2, the quick stop ramp then switch on disabled, and fault reaction
 * 0x605E = 2, the quick stop ramp, where the drive has them writable; 0x6085 quick stop
 * deceleration where the configuration gives it); 0x6060 = 10 (a refusal is
 * ARM_CO_FAULT_NO_CST), upload 0x6061 must be 10; NMT start; controlword 0x06, 0x07, 0x0F, each
 * confirmed by statusword & 0x6F (0x21, 0x23, 0x27) read back over SDO (a drive in fault: one fault
 * reset if the configuration allows). Every download is logged (arm_co_boot_t.log). */
#ifndef ARM_CO_BOOT_H
#define ARM_CO_BOOT_H

#include <stdint.h>

#include "arm/can_frame.h"
#include "arm/co_pdo.h"
#include "arm/co_sdo.h"

#define ARM_CO_BOOT_MAX_NODES 8u    /* nodes of one bus */
#define ARM_CO_BOOT_MAX_ACTIONS 56u /* steps of one node's sequence (the default uses 48) */
#define ARM_CO_BOOT_LOG_MAX (ARM_CO_BOOT_MAX_NODES * ARM_CO_BOOT_MAX_ACTIONS)
#define ARM_CO_PDO_MAX_ENTRIES 4u   /* mapping entries per PDO the configurator writes */

#define ARM_CO_PROFILE_402 0x0192u /* 0x1000's low word: CiA 402; the high word is the device's own */
#define ARM_CO_MODE_CST 10
#define ARM_CO_MODES_CST (1u << 9) /* 0x6502: cyclic synchronous torque supported */
#define ARM_CO_COB_NMT 0x000u
#define ARM_CO_COB_SYNC 0x080u
#define ARM_CO_COB_TPDO1 0x180u
#define ARM_CO_COB_RPDO1 0x200u
#define ARM_CO_COB_TPDO2 0x280u
#define ARM_CO_COB_HEARTBEAT 0x700u
#define ARM_CO_NMT_START 0x01u
#define ARM_CO_NMT_PREOP 0x80u
#define ARM_CO_PDO_INVALID 0x80000000u

/* The units a node's configuration (the drive table) gives: the drive's objects must equal them;
 * one the drive lacks is taken from the configuration. Never written. */
#define ARM_CO_EXPECT_RATED 0x01u
#define ARM_CO_EXPECT_ENCODER 0x02u
#define ARM_CO_EXPECT_GEAR 0x04u

/* Optional objects a drive turned out not to have (arm_co_node_t.absent). */
#define ARM_CO_ABSENT_1006 0x0001u
#define ARM_CO_ABSENT_1017 0x0002u
#define ARM_CO_ABSENT_1016 0x0004u
#define ARM_CO_ABSENT_6502 0x0008u
#define ARM_CO_ABSENT_6076 0x0010u
#define ARM_CO_ABSENT_608F 0x0020u
#define ARM_CO_ABSENT_6091 0x0040u
#define ARM_CO_ABSENT_6072 0x0080u
#define ARM_CO_ABSENT_605A 0x0100u /* absent or read-only: the drive's own quick stop option stands */
#define ARM_CO_ABSENT_605E 0x0200u /* the same for its fault reaction */
#define ARM_CO_ABSENT_6085 0x0400u

typedef struct {
    uint8_t n;                                  /* entries */
    uint32_t entry[ARM_CO_PDO_MAX_ENTRIES];     /* index << 16 | sub << 8 | bits */
    /* CiA 301 transmission type (sub2): 1-240 synchronous (an RPDO takes effect at the next SYNC,
     * a TPDO goes every n-th SYNC), 254/255 event-driven (an RPDO takes effect at once); 0: 1 */
    uint8_t trans;
} arm_co_pdo_map_t;

typedef struct {
    uint8_t node_id;             /* 1..127 */
    uint8_t expect;              /* ARM_CO_EXPECT_*: which of the three below the drive table gives */
    uint32_t rated_torque;       /* 0x6076, the motor's, in the drive's torque unit */
    /* 0x6076's unit, per N m: 1000 (mN m, CiA 402's; 0 means it) or 1000000 (µN m, as maxon's EPOS4
     * gives it: its firmware specification) */
    uint32_t torque_units_per_nm;
    uint32_t encoder_increments; /* 0x608F.1 (per motor revolution) */
    uint32_t gear_motor_revs;    /* 0x6091.1 */
    uint32_t gear_shaft_revs;    /* 0x6091.2 */
    uint32_t vendor_id;          /* 0x1018.1 expected; 0: any */
    uint32_t product_code;       /* 0x1018.2 expected; 0: any */
    uint32_t quick_stop_decel;   /* 0x6085 in the drive's own unit, written where it has it; 0: its own */
    /* the gear's efficiency, (0, 1]: the joint gets 0x6076 x gear x it (the drive table's; no object
     * holds it); 0 means 1, a lossless gear */
    float gear_efficiency;
    /* the joint's torque limit, N m: the drive must give it at the joint (0x6072 x 0x6076 x gear x
     * efficiency), else ARM_CO_FAULT_TORQUE_LIMIT before anything is written; 0: not checked */
    float joint_torque_limit_nm;
    /* 1: a drive without a settable 0x1016.1 (consumer heartbeat) boots: the drive table accepts
     * that a dead master leaves it applying its last torque; 0: such a drive is refused */
    uint8_t accept_no_master_watchdog;
} arm_co_node_config_t;

typedef struct {
    uint8_t n_nodes;
    arm_co_node_config_t node[ARM_CO_BOOT_MAX_NODES];
    arm_co_pdo_map_t rpdo1, tpdo1, tpdo2;
    uint32_t cycle_us;          /* 0x1006 */
    uint16_t heartbeat_ms;      /* 0x1017 */
    uint8_t master_id;          /* the master's node id in 0x1016.1 */
    uint16_t consumer_ms;       /* 0x1016.1 low 16 bits: the drive's timeout for the master */
    uint32_t sdo_timeout_us;
    uint8_t sdo_tries;
    /* A node that has not answered at all yet is asked its first question (0x1000) again, not
     * failed, until this long after the boot began: a drive that powers up after the master (a
     * slow one, or one whose bus comes up later) is still configured, as a CiA 302 master waits
     * for its slaves' boot-up. 0: no wait, `sdo_tries` alone. */
    uint32_t presence_timeout_us;
    uint32_t state_timeout_us;  /* per controlword step: the statusword must follow by then */
    uint8_t fault_reset;        /* 1: a drive in fault gets one fault reset (controlword 0x00, then
                                 * 0x80: bit 7's rising edge) before its failure is reported; 0: a
                                 * fault is reported at once (resetting is the operator's decision) */
} arm_co_boot_config_t;

/* The contract's defaults: RPDO1 6040+6071, TPDO1 6064+606C, TPDO2 6077+6041; 1 ms, 100 ms,
 * master 0x7F with 300 ms, SDO 50 ms x 3 tries, no presence wait, 500 ms per state. No nodes. */
void arm_co_boot_default_config(arm_co_boot_config_t *cfg);

typedef enum {
    ARM_CO_FAULT_NONE = 0,
    ARM_CO_FAULT_SDO_ABORT,     /* the node aborted a transfer (abort_code) */
    ARM_CO_FAULT_CLIENT_ABORT,  /* the master aborted the node's bad response (abort_code) */
    ARM_CO_FAULT_NO_ANSWER,     /* no answer after `tries` tries */
    ARM_CO_FAULT_WRONG_VALUE,   /* an uploaded value is not the expected one (value, expected) */
    ARM_CO_FAULT_STATE_TIMEOUT, /* the statusword did not follow the controlword (value: last sw) */
    ARM_CO_FAULT_DRIVE_FAULT,   /* the statusword shows fault (value: sw) */
    ARM_CO_FAULT_BAD_CONFIG,    /* the configuration cannot be run (node id, counts) */
    ARM_CO_FAULT_NO_CST,        /* no cyclic synchronous torque: 0x6502 bit 9 clear, or 0x6060 = 10 refused */
    ARM_CO_FAULT_UNITS_MISMATCH, /* a unit object differs from the drive table (value/value_den, expected/_den) */
    ARM_CO_FAULT_UNITS_MISSING, /* the drive lacks a unit object and the drive table gives none */
    ARM_CO_FAULT_BAD_UNITS,     /* the drive reports a unit of 0 (value/value_den) */
    ARM_CO_FAULT_TORQUE_LIMIT,  /* the joint's torque limit is more than the drive gives (limit_nm, units) */
    ARM_CO_FAULT_NO_WATCHDOG,   /* 0x1016.1 cannot be set (abort_code, value written; abort 0: a consumer time of 0) */
} arm_co_fault_code_t;

/* A node's units as the boot settled them: the drive's objects, or the drive table's value of one
 * the drive lacks (from_table). */
typedef struct {
    uint32_t rated_torque;           /* 0x6076, the motor's, in the drive's unit */
    uint32_t torque_units_per_nm;    /* that unit: 1000 mN m, 1000000 µN m */
    uint32_t encoder_increments;     /* 0x608F.1 */
    uint32_t encoder_revs;           /* 0x608F.2 */
    uint32_t gear_motor_revs, gear_shaft_revs; /* 0x6091.1, .2 */
    float gear_efficiency;           /* the drive table's (1: lossless) */
    uint16_t max_torque_permille;    /* 0x6072; 32767 if the drive has none */
    uint32_t modes;                  /* 0x6502 (0: the drive has none) */
    uint8_t from_table;              /* ARM_CO_EXPECT_* bits taken from the configuration */
} arm_co_drive_units_t;

typedef struct {
    arm_co_fault_code_t code;
    uint8_t node;
    uint16_t index;
    uint8_t sub;
    uint32_t abort_code;
    uint32_t value;
    uint32_t expected;
    uint32_t value_den, expected_den; /* a ratio's second term (0x608F.2, 0x6091.2) */
    uint32_t modes;                   /* NO_CST: 0x6502 as read */
    uint8_t has_modes;                /* NO_CST: 0x6502 was read (else the drive has none) */
    uint8_t tries;
    float limit_nm;                   /* TORQUE_LIMIT: the joint's torque limit */
    arm_co_drive_units_t units;       /* TORQUE_LIMIT: the drive's units, as settled */
} arm_co_fault_t;

const char *arm_co_fault_name(arm_co_fault_code_t code);

typedef struct {
    uint8_t node;
    uint16_t index;
    uint8_t sub;
    uint8_t len;   /* bytes */
    uint32_t value;
} arm_co_write_t;

typedef enum {
    ARM_CO_ACT_NMT = 0,  /* value: NMT command */
    ARM_CO_ACT_WRITE,    /* SDO download */
    ARM_CO_ACT_READ,     /* SDO upload; checked against value under mask (mask 0: recorded in its slot) */
    ARM_CO_ACT_CONTROL,  /* controlword value via SDO, then the statusword shows the state (mask) */
    ARM_CO_ACT_QUIESCE,  /* the statusword; if it does not show the state, the controlword, as CONTROL */
    ARM_CO_ACT_UNITS,    /* no transfer: the units read so far are checked and settled */
} arm_co_action_kind_t;

/* Where a READ's value goes (arm_co_node_t.read). */
typedef enum {
    ARM_CO_SLOT_NONE = 0, ARM_CO_SLOT_MODES, ARM_CO_SLOT_RATED, ARM_CO_SLOT_ENCODER, ARM_CO_SLOT_ENCODER_REVS,
    ARM_CO_SLOT_GEAR_MOTOR, ARM_CO_SLOT_GEAR_SHAFT, ARM_CO_SLOT_MAX_TORQUE, ARM_CO_SLOTS
} arm_co_slot_t;

#define ARM_CO_ACT_OPTIONAL 0x01u /* the drive may lack the object (CiA 301/402): an abort saying so skips it */
#define ARM_CO_ACT_IF_WRITABLE 0x02u /* ... or keep it read-only: its own value then stands */

typedef struct {
    uint8_t kind;        /* arm_co_action_kind_t */
    uint8_t sub;
    uint8_t len;
    uint8_t flags;       /* ARM_CO_ACT_OPTIONAL */
    uint8_t slot;        /* READ: arm_co_slot_t */
    uint16_t index;
    uint32_t value;
    uint32_t mask;       /* READ: bits that must equal value; CONTROL, QUIESCE: state | sw mask << 8 */
} arm_co_action_t;

typedef enum { ARM_CO_NODE_RUNNING = 0, ARM_CO_NODE_ENABLED, ARM_CO_NODE_FAILED } arm_co_node_state_t;

typedef struct {
    arm_co_node_state_t state;
    uint8_t n_actions;
    uint8_t next;                 /* the action under way */
    uint8_t started;              /* the action's first request is out */
    uint8_t control_phase;        /* CONTROL: 0 write cw, 1 read sw, 2 and 3 fault reset 0x00, 0x80 */
    uint8_t fault_resets;         /* fault resets done (at most one per node) */
    uint8_t cw_written;           /* CONTROL, QUIESCE: this action's controlword is out */
    uint8_t answered;             /* an SDO transfer of this node has ended well: it is there */
    uint64_t control_deadline_us;
    uint16_t statusword;
    uint32_t identity[4];         /* 0x1018.1..4 as read */
    uint16_t absent;              /* ARM_CO_ABSENT_*: optional objects the drive lacks */
    uint16_t have;                /* bit per arm_co_slot_t: read from the drive */
    uint32_t read[ARM_CO_SLOTS];  /* values read, per slot */
    arm_co_drive_units_t units;   /* settled by the ARM_CO_ACT_UNITS step */
    arm_co_action_t action[ARM_CO_BOOT_MAX_ACTIONS];
    arm_co_sdo_t sdo;
} arm_co_node_t;

typedef struct {
    arm_co_boot_config_t cfg;
    arm_co_node_t node[ARM_CO_BOOT_MAX_NODES];
    arm_co_fault_t fault;          /* the first failure (code NONE: none) */
    unsigned n_log;
    arm_co_write_t log[ARM_CO_BOOT_LOG_MAX];
    uint8_t nmt_pending[ARM_CO_BOOT_MAX_NODES]; /* NMT frame queued for node i (command + 1) */
    uint64_t next_heartbeat_us;
    uint8_t heartbeat_due;
    uint64_t start_us;             /* when the boot began (presence_timeout_us counts from it) */
} arm_co_boot_t;

/* Builds every node's sequence; -1 with fault ARM_CO_FAULT_BAD_CONFIG (node: the bad one) if a
 * node id is out of 1..127 or twice, a mapping has too many entries, or there are too many nodes. */
int arm_co_boot_init(arm_co_boot_t *b, const arm_co_boot_config_t *cfg, uint64_t now_us);
/* Node i's units in SI (arm/co_pdo.h), once the boot has settled them (every node enabled): 0, or
 * -1 if the node has none yet or they cannot be built. */
int arm_co_boot_units(const arm_co_boot_t *b, unsigned i, arm_co_units_t *u);
/* A received frame (SDO answers; anything else is ignored). */
void arm_co_boot_rx(arm_co_boot_t *b, const arm_can_frame_t *f, uint64_t now_us);
/* One period: timeouts, the next request of every node. Returns 1 while any node still runs,
 * 0 when every node is enabled, -1 once a node failed (b->fault says which and why; the others
 * stop where they are). */
int arm_co_boot_step(arm_co_boot_t *b, uint64_t now_us);
/* The next frame to send (1), or 0 when nothing is due. */
int arm_co_boot_take_tx(arm_co_boot_t *b, arm_can_frame_t *out);

#endif
