/* The CiA 402 boot configurator (arm/co_boot.h). Each node's sequence is built once, at init, as
 * a list of actions; the step then only walks the lists, so what is written is fixed before the
 * first frame goes out (and the log is the list's WRITE actions, in the order they were done). */
#include "arm/co_boot.h"

#include <stddef.h>

#define SW_STATE_MASK 0x006Fu
#define SW_DISABLED_MASK 0x004Fu /* switch on disabled: bit 5 (quick stop) is not part of it */
#define SW_FAULT 0x0008u
/* A CONTROL or QUIESCE action's mask field: the state expected, and the statusword bits that show it. */
#define SW_EXPECT(state, mask) ((uint32_t)(state) | ((uint32_t)(mask) << 8))

void arm_co_boot_default_config(arm_co_boot_config_t *cfg)
{
    *cfg = (arm_co_boot_config_t){0};
    cfg->rpdo1 = (arm_co_pdo_map_t){2u, {0x60400010u, 0x60710010u, 0u, 0u}, 1u};
    cfg->tpdo1 = (arm_co_pdo_map_t){2u, {0x60640020u, 0x606C0020u, 0u, 0u}, 1u};
    cfg->tpdo2 = (arm_co_pdo_map_t){2u, {0x60770010u, 0x60410010u, 0u, 0u}, 1u};
    cfg->cycle_us = 1000u;
    cfg->heartbeat_ms = 100u;
    cfg->master_id = 0x7Fu;
    cfg->consumer_ms = 300u;
    cfg->sdo_timeout_us = 50000u;
    cfg->sdo_tries = 3u;
    cfg->state_timeout_us = 500000u;
}

const char *arm_co_fault_name(arm_co_fault_code_t code)
{
    switch (code) {
    case ARM_CO_FAULT_NONE: return "none";
    case ARM_CO_FAULT_SDO_ABORT: return "sdo_abort";
    case ARM_CO_FAULT_CLIENT_ABORT: return "bad_response";
    case ARM_CO_FAULT_NO_ANSWER: return "no_answer";
    case ARM_CO_FAULT_WRONG_VALUE: return "wrong_value";
    case ARM_CO_FAULT_STATE_TIMEOUT: return "state_timeout";
    case ARM_CO_FAULT_DRIVE_FAULT: return "drive_fault";
    case ARM_CO_FAULT_BAD_CONFIG: return "bad_config";
    case ARM_CO_FAULT_NO_CST: return "no_cst";
    case ARM_CO_FAULT_UNITS_MISMATCH: return "units_mismatch";
    case ARM_CO_FAULT_UNITS_MISSING: return "units_missing";
    case ARM_CO_FAULT_BAD_UNITS: return "bad_units";
    case ARM_CO_FAULT_TORQUE_LIMIT: return "torque_limit";
    case ARM_CO_FAULT_NO_WATCHDOG: return "no_master_watchdog";
    }
    return "unknown";
}

static void add_full(arm_co_node_t *n, uint8_t kind, uint16_t index, uint8_t sub, uint8_t len, uint32_t value,
                     uint32_t mask, uint8_t flags, uint8_t slot)
{
    if (n->n_actions < ARM_CO_BOOT_MAX_ACTIONS) { /* sized for the longest sequence: init checks */
        n->action[n->n_actions++] = (arm_co_action_t){kind, sub, len, flags, slot, index, value, mask};
    }
}

static void add(arm_co_node_t *n, uint8_t kind, uint16_t index, uint8_t sub, uint8_t len, uint32_t value,
                uint32_t mask)
{
    add_full(n, kind, index, sub, len, value, mask, 0u, ARM_CO_SLOT_NONE);
}

/* A unit object read if the drive has it (CiA 402 makes them optional), into its slot. */
static void add_unit(arm_co_node_t *n, uint16_t index, uint8_t sub, uint8_t slot)
{
    add_full(n, ARM_CO_ACT_READ, index, sub, 4u, 0u, 0u, ARM_CO_ACT_OPTIONAL, slot);
}

static void add_pdo(arm_co_node_t *n, uint16_t comm, uint16_t map, uint32_t cob, const arm_co_pdo_map_t *m)
{
    add(n, ARM_CO_ACT_WRITE, comm, 1u, 4u, cob | ARM_CO_PDO_INVALID, 0u);
    add(n, ARM_CO_ACT_WRITE, map, 0u, 1u, 0u, 0u);
    for (uint8_t i = 0; i < m->n && i < ARM_CO_PDO_MAX_ENTRIES; ++i) {
        add(n, ARM_CO_ACT_WRITE, map, (uint8_t)(i + 1u), 4u, m->entry[i], 0u);
    }
    add(n, ARM_CO_ACT_WRITE, map, 0u, 1u, m->n, 0u);
    add(n, ARM_CO_ACT_WRITE, comm, 2u, 1u, m->trans != 0u ? m->trans : 1u, 0u); /* [1: every SYNC] */
    add(n, ARM_CO_ACT_WRITE, comm, 1u, 4u, cob, 0u);
}

static void build(arm_co_node_t *n, const arm_co_boot_config_t *cfg, const arm_co_node_config_t *nc)
{
    const uint32_t id = nc->node_id;
    n->n_actions = 0u;
    add(n, ARM_CO_ACT_NMT, 0u, 0u, 0u, ARM_CO_NMT_PREOP, 0u);
    add(n, ARM_CO_ACT_READ, 0x1000u, 0u, 4u, ARM_CO_PROFILE_402, 0x0000FFFFu); /* the profile word only */
    add(n, ARM_CO_ACT_READ, 0x1018u, 1u, 4u, nc->vendor_id, nc->vendor_id ? 0xFFFFFFFFu : 0u);
    add(n, ARM_CO_ACT_READ, 0x1018u, 2u, 4u, nc->product_code, nc->product_code ? 0xFFFFFFFFu : 0u);
    add(n, ARM_CO_ACT_READ, 0x1018u, 3u, 4u, 0u, 0u);
    add(n, ARM_CO_ACT_READ, 0x1018u, 4u, 4u, 0u, 0u);
    /* the drive's modes and units, read before anything is written: a drive this controller cannot
     * run, or whose units are not the table's, is refused untouched */
    add_unit(n, 0x6502u, 0u, ARM_CO_SLOT_MODES);
    add_unit(n, 0x6076u, 0u, ARM_CO_SLOT_RATED);
    add_unit(n, 0x608Fu, 1u, ARM_CO_SLOT_ENCODER);
    add_unit(n, 0x608Fu, 2u, ARM_CO_SLOT_ENCODER_REVS);
    add_unit(n, 0x6091u, 1u, ARM_CO_SLOT_GEAR_MOTOR);
    add_unit(n, 0x6091u, 2u, ARM_CO_SLOT_GEAR_SHAFT);
    add_unit(n, 0x6072u, 0u, ARM_CO_SLOT_MAX_TORQUE);
    add(n, ARM_CO_ACT_UNITS, 0u, 0u, 0u, 0u, 0u);
    /* A drive left enabled (a master restarted) takes no new mode or scaling (0x08000022): switch
     * on disabled first. A fresh drive already is, and nothing is written. */
    add(n, ARM_CO_ACT_QUIESCE, 0x6040u, 0u, 2u, 0x0000u, SW_EXPECT(0x40u, SW_DISABLED_MASK));
    add_pdo(n, 0x1400u, 0x1600u, ARM_CO_COB_RPDO1 + id, &cfg->rpdo1);
    add_pdo(n, 0x1800u, 0x1A00u, ARM_CO_COB_TPDO1 + id, &cfg->tpdo1);
    add_pdo(n, 0x1801u, 0x1A01u, ARM_CO_COB_TPDO2 + id, &cfg->tpdo2);
    /* CiA 301 makes these optional: written where the drive has them. 0x1016 too, but a drive
     * without it is refused unless the configuration accepts that (step_node) */
    add_full(n, ARM_CO_ACT_WRITE, 0x1006u, 0u, 4u, cfg->cycle_us, 0u, ARM_CO_ACT_OPTIONAL, ARM_CO_SLOT_NONE);
    add_full(n, ARM_CO_ACT_WRITE, 0x1017u, 0u, 2u, cfg->heartbeat_ms, 0u, ARM_CO_ACT_OPTIONAL, ARM_CO_SLOT_NONE);
    add_full(n, ARM_CO_ACT_WRITE, 0x1016u, 1u, 4u, ((uint32_t)cfg->master_id << 16) | cfg->consumer_ms, 0u,
             ARM_CO_ACT_OPTIONAL, ARM_CO_SLOT_NONE);
    /* how the drive stops: the quick stop ramp, then switch on disabled (its brake closed); a fault:
     * the quick stop ramp (CiA 402 option codes 2); the ramp's deceleration where the table gives it */
    add_full(n, ARM_CO_ACT_WRITE, 0x605Au, 0u, 2u, 2u, 0u, ARM_CO_ACT_OPTIONAL | ARM_CO_ACT_IF_WRITABLE, ARM_CO_SLOT_NONE);
    add_full(n, ARM_CO_ACT_WRITE, 0x605Eu, 0u, 2u, 2u, 0u, ARM_CO_ACT_OPTIONAL | ARM_CO_ACT_IF_WRITABLE, ARM_CO_SLOT_NONE);
    if (nc->quick_stop_decel != 0u) {
        add_full(n, ARM_CO_ACT_WRITE, 0x6085u, 0u, 4u, nc->quick_stop_decel, 0u, ARM_CO_ACT_OPTIONAL, ARM_CO_SLOT_NONE);
    }
    add(n, ARM_CO_ACT_WRITE, 0x6060u, 0u, 1u, (uint32_t)ARM_CO_MODE_CST, 0u);
    add(n, ARM_CO_ACT_READ, 0x6061u, 0u, 1u, (uint32_t)ARM_CO_MODE_CST, 0xFFu);
    add(n, ARM_CO_ACT_NMT, 0u, 0u, 0u, ARM_CO_NMT_START, 0u);
    add(n, ARM_CO_ACT_CONTROL, 0x6040u, 0u, 2u, 0x0006u, SW_EXPECT(0x21u, SW_STATE_MASK));
    add(n, ARM_CO_ACT_CONTROL, 0x6040u, 0u, 2u, 0x0007u, SW_EXPECT(0x23u, SW_STATE_MASK));
    add(n, ARM_CO_ACT_CONTROL, 0x6040u, 0u, 2u, 0x000Fu, SW_EXPECT(0x27u, SW_STATE_MASK));
}

/* NMT, 0x1000, 0x1018.1-4, 7 unit reads and their check, the quiesce, 3 PDOs x 5 + their entries,
 * 0x1006, 0x1017, 0x1016, 0x605A, 0x605E, 0x6085, 0x6060, 0x6061, NMT start, 3 controlwords. */
static unsigned sequence_length(const arm_co_boot_config_t *cfg)
{
    return 6u + 8u + 1u + 3u * 5u + cfg->rpdo1.n + cfg->tpdo1.n + cfg->tpdo2.n + 3u + 3u + 2u + 1u + 3u;
}

static int bad_config(arm_co_boot_t *b, uint8_t node, uint32_t value)
{
    b->fault = (arm_co_fault_t){0};
    b->fault.code = ARM_CO_FAULT_BAD_CONFIG;
    b->fault.node = node;
    b->fault.value = value;
    return -1;
}

int arm_co_boot_init(arm_co_boot_t *b, const arm_co_boot_config_t *cfg, uint64_t now_us)
{
    b->cfg = *cfg;
    b->fault = (arm_co_fault_t){0};
    b->n_log = 0u;
    b->next_heartbeat_us = now_us;
    b->heartbeat_due = 0u;
    b->start_us = now_us;
    if (cfg->n_nodes == 0u || cfg->n_nodes > ARM_CO_BOOT_MAX_NODES) {
        return bad_config(b, 0u, cfg->n_nodes);
    }
    if (cfg->rpdo1.n > ARM_CO_PDO_MAX_ENTRIES || cfg->tpdo1.n > ARM_CO_PDO_MAX_ENTRIES ||
        cfg->tpdo2.n > ARM_CO_PDO_MAX_ENTRIES ||
        sequence_length(cfg) + 3u > ARM_CO_BOOT_MAX_ACTIONS) { /* + a fault reset's 3 logged writes */
        return bad_config(b, 0u, sequence_length(cfg));
    }
    for (uint8_t i = 0; i < cfg->n_nodes; ++i) {
        const arm_co_node_config_t *nc = &cfg->node[i];
        if (nc->node_id == 0u || nc->node_id > 127u || nc->node_id == cfg->master_id) {
            return bad_config(b, nc->node_id, nc->node_id);
        }
        for (uint8_t j = 0; j < i; ++j) {
            if (cfg->node[j].node_id == nc->node_id) {
                return bad_config(b, nc->node_id, nc->node_id);
            }
        }
        if (cfg->consumer_ms == 0u && !nc->accept_no_master_watchdog) {
            /* a consumer time of 0 turns the drive's watchdog on the master off */
            b->fault = (arm_co_fault_t){0};
            b->fault.code = ARM_CO_FAULT_NO_WATCHDOG;
            b->fault.node = nc->node_id;
            b->fault.index = 0x1016u;
            b->fault.sub = 1u;
            return -1;
        }
        if (!(nc->gear_efficiency >= 0.0f && nc->gear_efficiency <= 1.0f) || !(nc->joint_torque_limit_nm >= 0.0f)) {
            return bad_config(b, nc->node_id, nc->node_id);
        }
        arm_co_node_t *n = &b->node[i];
        *n = (arm_co_node_t){0};
        n->state = ARM_CO_NODE_RUNNING;
        build(n, cfg, nc);
        arm_co_sdo_init(&n->sdo, nc->node_id, cfg->sdo_timeout_us, cfg->sdo_tries);
        b->nmt_pending[i] = 0u;
    }
    return 0;
}

void arm_co_boot_rx(arm_co_boot_t *b, const arm_can_frame_t *f, uint64_t now_us)
{
    for (uint8_t i = 0; i < b->cfg.n_nodes; ++i) {
        if (arm_co_sdo_rx(&b->node[i].sdo, f, now_us)) {
            return;
        }
    }
}

static void fail(arm_co_boot_t *b, arm_co_node_t *n, arm_co_fault_code_t code, const arm_co_action_t *a,
                 uint16_t index, uint32_t value, uint32_t expected)
{
    n->state = ARM_CO_NODE_FAILED;
    if (b->fault.code != ARM_CO_FAULT_NONE) {
        return; /* the first failure is the one reported */
    }
    b->fault = (arm_co_fault_t){0};
    b->fault.code = code;
    b->fault.node = n->sdo.node;
    b->fault.index = index;
    b->fault.sub = index == a->index ? a->sub : 0u;
    b->fault.abort_code = n->sdo.abort_code;
    b->fault.value = value;
    b->fault.expected = expected;
    b->fault.tries = n->sdo.tries;
}

static void fail_no_cst(arm_co_boot_t *b, arm_co_node_t *n, const arm_co_action_t *a, uint32_t abort_code)
{
    fail(b, n, ARM_CO_FAULT_NO_CST, a, a->index, (uint32_t)ARM_CO_MODE_CST, 0u);
    if (b->fault.code == ARM_CO_FAULT_NO_CST && b->fault.node == n->sdo.node) {
        b->fault.abort_code = abort_code;
        b->fault.modes = n->read[ARM_CO_SLOT_MODES];
        b->fault.has_modes = (n->have >> ARM_CO_SLOT_MODES) & 1u;
    }
}

/* The SDO transfer of action a ended (DONE, ABORTED or TIMEOUT): 1 if it succeeded. */
static int transfer_ok(arm_co_boot_t *b, arm_co_node_t *n, const arm_co_action_t *a)
{
    if (n->sdo.status == ARM_CO_SDO_DONE) {
        return 1;
    }
    const arm_co_fault_code_t code = n->sdo.status == ARM_CO_SDO_TIMEOUT ? ARM_CO_FAULT_NO_ANSWER
                                     : n->sdo.abort_by_server        ? ARM_CO_FAULT_SDO_ABORT
                                                                     : ARM_CO_FAULT_CLIENT_ABORT;
    /* the drive refuses mode 10 (a value out of its range, no such object): it has no CST. A state
     * abort (0x08000022) is not about the mode. */
    if (code == ARM_CO_FAULT_SDO_ABORT && a->kind == ARM_CO_ACT_WRITE && a->index == 0x6060u &&
        n->sdo.abort_code != ARM_CO_ABORT_STATE) {
        fail_no_cst(b, n, a, n->sdo.abort_code);
        return 0;
    }
    fail(b, n, code, a, n->sdo.index, 0u, 0u);
    return 0;
}

/* The drive's server said it has no such object or sub-index. */
static int said_absent(const arm_co_node_t *n)
{
    return n->sdo.status == ARM_CO_SDO_ABORTED && n->sdo.abort_by_server &&
           (n->sdo.abort_code == ARM_CO_ABORT_NO_SUB || n->sdo.abort_code == ARM_CO_ABORT_NO_OBJECT);
}

/* An optional object the drive lacks (a recorded identity entry, an optional read or write), or
 * keeps read-only where it may. */
static int optional_absent(const arm_co_node_t *n, const arm_co_action_t *a)
{
    const int identity = a->kind == ARM_CO_ACT_READ && a->mask == 0u && a->index == 0x1018u && a->sub >= 2u;
    const int read_only = (a->flags & ARM_CO_ACT_IF_WRITABLE) != 0u && n->sdo.status == ARM_CO_SDO_ABORTED &&
                          n->sdo.abort_by_server && n->sdo.abort_code == ARM_CO_ABORT_READ_ONLY;
    return ((identity || (a->flags & ARM_CO_ACT_OPTIONAL) != 0u) && said_absent(n)) || read_only;
}

static uint16_t absent_bit(uint16_t index)
{
    switch (index) {
    case 0x1006u: return ARM_CO_ABSENT_1006;
    case 0x1017u: return ARM_CO_ABSENT_1017;
    case 0x1016u: return ARM_CO_ABSENT_1016;
    case 0x6502u: return ARM_CO_ABSENT_6502;
    case 0x6076u: return ARM_CO_ABSENT_6076;
    case 0x608Fu: return ARM_CO_ABSENT_608F;
    case 0x6091u: return ARM_CO_ABSENT_6091;
    case 0x6072u: return ARM_CO_ABSENT_6072;
    case 0x605Au: return ARM_CO_ABSENT_605A;
    case 0x605Eu: return ARM_CO_ABSENT_605E;
    case 0x6085u: return ARM_CO_ABSENT_6085;
    default: return 0u;
    }
}

static int has(const arm_co_node_t *n, arm_co_slot_t slot)
{
    return (n->have >> slot) & 1u;
}

/* One unit: the drive's value (num/den; den_slot NONE: a plain value), or the configuration's where
 * the drive lacks it. 0, or -1 after fail(). */
static int settle(arm_co_boot_t *b, arm_co_node_t *n, const arm_co_action_t *a, uint16_t index, arm_co_slot_t num_slot,
                  arm_co_slot_t den_slot, uint8_t expect_bit, uint32_t table_num, uint32_t table_den, uint32_t *num,
                  uint32_t *den)
{
    const arm_co_node_config_t *nc = &b->cfg.node[n - b->node];
    const int given = (nc->expect & expect_bit) != 0u;
    const uint8_t sub = (uint8_t)(den_slot == ARM_CO_SLOT_NONE ? 0u : 1u);
    if (!has(n, num_slot)) {
        if (!given) {
            fail(b, n, ARM_CO_FAULT_UNITS_MISSING, a, index, 0u, 0u);
            if (b->fault.node == n->sdo.node) b->fault.sub = sub;
            return -1;
        }
        *num = table_num;
        *den = table_den;
        n->units.from_table |= expect_bit;
        return 0;
    }
    *num = n->read[num_slot];
    *den = den_slot != ARM_CO_SLOT_NONE && has(n, den_slot) ? n->read[den_slot] : 1u;
    const int zero = *num == 0u || *den == 0u;
    /* a ratio compares across: num/den == table_num/table_den */
    const int differs = given && (uint64_t)*num * table_den != (uint64_t)table_num * *den;
    if (zero || differs) {
        fail(b, n, zero ? ARM_CO_FAULT_BAD_UNITS : ARM_CO_FAULT_UNITS_MISMATCH, a, index, *num, table_num);
        if (b->fault.node == n->sdo.node) {
            b->fault.sub = sub;
            b->fault.value_den = den_slot == ARM_CO_SLOT_NONE ? 0u : *den;
            b->fault.expected_den = den_slot == ARM_CO_SLOT_NONE ? 0u : table_den;
        }
        return -1;
    }
    return 0;
}

/* After the reads: a drive without CST is refused; the units are the drive's, checked against the
 * configuration, which stands in for what the drive lacks. 0, or -1 after fail(). */
static int settle_units(arm_co_boot_t *b, arm_co_node_t *n, const arm_co_action_t *a)
{
    const arm_co_node_config_t *nc = &b->cfg.node[n - b->node];
    arm_co_drive_units_t *u = &n->units;
    *u = (arm_co_drive_units_t){0};
    u->modes = has(n, ARM_CO_SLOT_MODES) ? n->read[ARM_CO_SLOT_MODES] : 0u;
    if (has(n, ARM_CO_SLOT_MODES) && (u->modes & ARM_CO_MODES_CST) == 0u) {
        const arm_co_action_t modes = {ARM_CO_ACT_READ, 0u, 4u, 0u, 0u, 0x6502u, 0u, 0u};
        fail_no_cst(b, n, &modes, 0u);
        return -1;
    }
    uint32_t one = 1u;
    u->torque_units_per_nm = nc->torque_units_per_nm != 0u ? nc->torque_units_per_nm : 1000u;
    if (settle(b, n, a, 0x6076u, ARM_CO_SLOT_RATED, ARM_CO_SLOT_NONE, ARM_CO_EXPECT_RATED, nc->rated_torque, 1u,
               &u->rated_torque, &one) != 0 ||
        settle(b, n, a, 0x608Fu, ARM_CO_SLOT_ENCODER, ARM_CO_SLOT_ENCODER_REVS, ARM_CO_EXPECT_ENCODER,
               nc->encoder_increments, 1u, &u->encoder_increments, &u->encoder_revs) != 0 ||
        settle(b, n, a, 0x6091u, ARM_CO_SLOT_GEAR_MOTOR, ARM_CO_SLOT_GEAR_SHAFT, ARM_CO_EXPECT_GEAR, nc->gear_motor_revs,
               nc->gear_shaft_revs, &u->gear_motor_revs, &u->gear_shaft_revs) != 0) {
        return -1;
    }
    const uint32_t max = n->read[ARM_CO_SLOT_MAX_TORQUE];
    u->max_torque_permille = !has(n, ARM_CO_SLOT_MAX_TORQUE) ? 32767u : max > 32767u ? 32767u : (uint16_t)max;
    u->gear_efficiency = nc->gear_efficiency > 0.0f ? nc->gear_efficiency : 1.0f;
    if (u->max_torque_permille == 0u) {
        fail(b, n, ARM_CO_FAULT_BAD_UNITS, a, 0x6072u, 0u, 0u); /* a drive that may give no torque */
        return -1;
    }
    arm_co_units_t si;
    if (nc->joint_torque_limit_nm > 0.0f &&
        arm_co_units_init(&si, u->rated_torque, u->torque_units_per_nm, (double)u->gear_efficiency,
                          u->encoder_increments, u->encoder_revs, u->gear_motor_revs, u->gear_shaft_revs,
                          (int16_t)u->max_torque_permille) == 0 &&
        arm_co_units_max_joint_torque_nm(&si) < (double)nc->joint_torque_limit_nm * (1.0 - 1e-6)) {
        /* the controller would ask for torques the drive cannot give: refused before anything is written */
        fail(b, n, ARM_CO_FAULT_TORQUE_LIMIT, a, 0x6072u, u->max_torque_permille, 0u);
        if (b->fault.node == n->sdo.node) {
            b->fault.limit_nm = nc->joint_torque_limit_nm;
            b->fault.units = *u;
        }
        return -1;
    }
    return 0;
}

int arm_co_boot_units(const arm_co_boot_t *b, unsigned i, arm_co_units_t *u)
{
    if (i >= b->cfg.n_nodes || b->node[i].state != ARM_CO_NODE_ENABLED) {
        return -1;
    }
    const arm_co_drive_units_t *d = &b->node[i].units;
    return arm_co_units_init(u, d->rated_torque, d->torque_units_per_nm, (double)d->gear_efficiency,
                             d->encoder_increments, d->encoder_revs, d->gear_motor_revs, d->gear_shaft_revs,
                             (int16_t)d->max_torque_permille);
}

static void log_value(arm_co_boot_t *b, const arm_co_node_t *n, uint16_t index, uint8_t sub, uint8_t len,
                      uint32_t value)
{
    if (b->n_log < ARM_CO_BOOT_LOG_MAX) { /* sized for every node's sequence; a fault reset's two
                                           * writes fit in the room ARM_CO_BOOT_MAX_ACTIONS leaves */
        b->log[b->n_log++] = (arm_co_write_t){n->sdo.node, index, sub, len, value};
    }
}

static void log_write(arm_co_boot_t *b, const arm_co_node_t *n, const arm_co_action_t *a)
{
    log_value(b, n, a->index, a->sub, a->len, a->value);
}

static void download(arm_co_node_t *n, uint16_t index, uint8_t sub, uint8_t len, uint32_t value, uint64_t now)
{
    uint8_t d[4];
    for (unsigned k = 0; k < 4u; ++k) {
        d[k] = (uint8_t)(value >> (8u * k));
    }
    (void)arm_co_sdo_download(&n->sdo, index, sub, d, len, now);
}

/* Advances node i by what its SDO channel finished; starts the next request. */
static void step_node(arm_co_boot_t *b, uint8_t i, uint64_t now)
{
    arm_co_node_t *n = &b->node[i];
    arm_co_sdo_tick(&n->sdo, now);
    /* A bounded walk: at most every action once per step (NMT actions finish at once). */
    for (unsigned guard = 0; guard < ARM_CO_BOOT_MAX_ACTIONS && n->state == ARM_CO_NODE_RUNNING; ++guard) {
        if (n->next >= n->n_actions) {
            n->state = ARM_CO_NODE_ENABLED;
            return;
        }
        const arm_co_action_t *a = &n->action[n->next];
        if (!n->started) {
            n->started = 1u;
            n->control_phase = 0u;
            switch (a->kind) {
            case ARM_CO_ACT_NMT:
                b->nmt_pending[i] = (uint8_t)a->value;
                n->started = 0u;
                n->next++;
                continue;
            case ARM_CO_ACT_WRITE:
                download(n, a->index, a->sub, a->len, a->value, now);
                return;
            case ARM_CO_ACT_READ:
                (void)arm_co_sdo_upload(&n->sdo, a->index, a->sub, now);
                return;
            case ARM_CO_ACT_UNITS:
                n->started = 0u;
                if (settle_units(b, n, a) != 0) {
                    return;
                }
                n->next++;
                continue;
            case ARM_CO_ACT_QUIESCE: /* the statusword first: written only if not there yet */
                n->control_deadline_us = now + b->cfg.state_timeout_us;
                n->control_phase = 1u;
                n->cw_written = 0u;
                (void)arm_co_sdo_upload(&n->sdo, 0x6041u, 0u, now);
                return;
            case ARM_CO_ACT_CONTROL:
            default:
                n->control_deadline_us = now + b->cfg.state_timeout_us;
                download(n, a->index, a->sub, a->len, a->value, now);
                return;
            }
        }
        if (n->sdo.status == ARM_CO_SDO_BUSY) {
            return;
        }
        if (n->sdo.status == ARM_CO_SDO_TIMEOUT && !n->answered &&
            now - b->start_us < b->cfg.presence_timeout_us) {
            (void)arm_co_sdo_upload(&n->sdo, a->index, a->sub, now); /* not there yet: ask again */
            return;
        }
        /* CiA 301 makes 0x1018.1 mandatory and 2-4 optional (recorded as 0 where the drive lacks
         * them), and 0x1006, 0x1016, 0x1017 too; CiA 402 the unit objects: skipped where absent */
        const int absent = optional_absent(n, a);
        if (a->kind == ARM_CO_ACT_WRITE && a->index == 0x1016u && n->sdo.status == ARM_CO_SDO_ABORTED) {
            /* the drive's watchdog on the master cannot be set: without it a dead master leaves the
             * drive applying its last torque. Refused, unless the drive table accepts that. */
            if (!b->cfg.node[i].accept_no_master_watchdog) {
                fail(b, n, ARM_CO_FAULT_NO_WATCHDOG, a, 0x1016u, a->value, 0u);
                return;
            }
            n->answered = 1u;
            n->absent |= ARM_CO_ABSENT_1016;
            n->started = 0u;
            n->next++;
            continue;
        }
        if (!absent && !transfer_ok(b, n, a)) {
            return;
        }
        n->answered = 1u;
        if (absent) {
            n->absent |= absent_bit(a->index);
        } else if (a->kind == ARM_CO_ACT_WRITE) {
            log_write(b, n, a);
        }
        if (a->kind == ARM_CO_ACT_READ) {
            const uint32_t v = absent ? 0u : arm_co_sdo_u32(&n->sdo);
            if (a->index == 0x1018u && a->sub >= 1u && a->sub <= 4u) {
                n->identity[a->sub - 1u] = v;
            }
            if (!absent && a->slot != ARM_CO_SLOT_NONE && a->slot < ARM_CO_SLOTS) {
                n->read[a->slot] = v;
                n->have |= (uint16_t)(1u << a->slot);
            }
            if ((v & a->mask) != (a->value & a->mask)) {
                fail(b, n, ARM_CO_FAULT_WRONG_VALUE, a, a->index, v, a->value);
                return;
            }
        } else if (a->kind != ARM_CO_ACT_WRITE) { /* CONTROL: the controlword is in; read the statusword until it follows */
            if (n->control_phase == 0u) {
                log_write(b, n, a);
                n->cw_written = 1u;
                n->control_phase = 1u;
                (void)arm_co_sdo_upload(&n->sdo, 0x6041u, 0u, now);
                return;
            }
            if (n->control_phase == 2u) { /* 0x00 is in: now bit 7's rising edge */
                log_value(b, n, 0x6040u, 0u, 2u, 0x0000u);
                n->control_phase = 3u;
                download(n, 0x6040u, 0u, 2u, 0x0080u, now);
                return;
            }
            if (n->control_phase == 3u) { /* reset sent: the step's own controlword again */
                log_value(b, n, 0x6040u, 0u, 2u, 0x0080u);
                n->fault_resets++;
                n->control_phase = 0u;
                n->control_deadline_us = now + b->cfg.state_timeout_us;
                download(n, a->index, a->sub, a->len, a->value, now);
                return;
            }
            n->statusword = (uint16_t)arm_co_sdo_u32(&n->sdo);
            if (n->statusword & SW_FAULT) {
                if (b->cfg.fault_reset && n->fault_resets == 0u) {
                    n->control_phase = 2u;
                    download(n, 0x6040u, 0u, 2u, 0x0000u, now);
                    return;
                }
                fail(b, n, ARM_CO_FAULT_DRIVE_FAULT, a, 0x6041u, n->statusword, a->mask);
                return;
            }
            if ((n->statusword & (a->mask >> 8)) != (a->mask & 0xFFu)) {
                if (!n->cw_written) { /* QUIESCE: not there yet, so the controlword goes out */
                    n->control_phase = 0u;
                    download(n, a->index, a->sub, a->len, a->value, now);
                    return;
                }
                if (now >= n->control_deadline_us) {
                    fail(b, n, ARM_CO_FAULT_STATE_TIMEOUT, a, 0x6041u, n->statusword, a->mask);
                    return;
                }
                (void)arm_co_sdo_upload(&n->sdo, 0x6041u, 0u, now);
                return; /* read again next step: one request per node per period */
            }
        }
        n->started = 0u;
        n->next++;
    }
}

int arm_co_boot_step(arm_co_boot_t *b, uint64_t now_us)
{
    if (b->fault.code != ARM_CO_FAULT_NONE) {
        return -1;
    }
    if (now_us >= b->next_heartbeat_us && b->cfg.heartbeat_ms > 0u) {
        b->heartbeat_due = 1u;
        b->next_heartbeat_us = now_us + (uint64_t)b->cfg.heartbeat_ms * 1000u;
    }
    unsigned running = 0u;
    for (uint8_t i = 0; i < b->cfg.n_nodes; ++i) {
        step_node(b, i, now_us);
        if (b->node[i].state == ARM_CO_NODE_RUNNING) {
            ++running;
        }
    }
    if (b->fault.code != ARM_CO_FAULT_NONE) {
        return -1;
    }
    return running ? 1 : 0;
}

int arm_co_boot_take_tx(arm_co_boot_t *b, arm_can_frame_t *out)
{
    for (uint8_t i = 0; i < b->cfg.n_nodes; ++i) {
        if (b->nmt_pending[i]) {
            *out = (arm_can_frame_t){0};
            out->id = ARM_CO_COB_NMT;
            out->len = 2u;
            out->data[0] = b->nmt_pending[i];
            out->data[1] = b->cfg.node[i].node_id;
            b->nmt_pending[i] = 0u;
            return 1;
        }
    }
    if (b->heartbeat_due) { /* the master's own heartbeat, which the drives consume (0x1016) */
        *out = (arm_can_frame_t){0};
        out->id = ARM_CO_COB_HEARTBEAT + b->cfg.master_id;
        out->len = 1u;
        out->data[0] = 0x05u; /* operational */
        b->heartbeat_due = 0u;
        return 1;
    }
    for (uint8_t i = 0; i < b->cfg.n_nodes; ++i) {
        if (arm_co_sdo_take_tx(&b->node[i].sdo, out)) {
            return 1;
        }
    }
    return 0;
}
