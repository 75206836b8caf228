#include "sim_canopen_node.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define COB_NMT 0x000u
#define COB_EMCY 0x080u
#define COB_SDO_TX 0x580u
#define COB_SDO_RX 0x600u
#define COB_HEARTBEAT 0x700u
#define COB_INVALID 0x80000000u
#define COB_FRAME 0x20000000u /* 29-bit ids: not on this drive */
#define COB_RTR 0x40000000u

#define NMT_PRE_OPERATIONAL 0x80u
#define NMT_RESET_NODE 0x81u
#define NMT_RESET_COMM 0x82u

#define ERR_REG_GENERIC 0x01u
#define ERR_REG_CURRENT 0x02u
#define ERR_REG_COMMUNICATION 0x10u

static const uint16_t RPDO_COMM = 0x1400u, RPDO_MAP = 0x1600u, TPDO_COMM = 0x1800u, TPDO_MAP = 0x1A00u;

static void queue(sim_co_node_t *n, uint32_t id, const uint8_t *data, unsigned len)
{
    if (n->n_out == SIM_CO_OUT_MAX) {
        n->out_dropped++;
        return;
    }
    arm_can_frame_t *f = &n->out[n->n_out++];
    memset(f, 0, sizeof(*f));
    f->id = id;
    f->len = (uint8_t)len;
    memcpy(f->data, data, len);
}

static void heartbeat(sim_co_node_t *n)
{
    const uint8_t s = n->nmt;
    queue(n, COB_HEARTBEAT + n->id, &s, 1u);
}

static void emcy(sim_co_node_t *n, uint16_t code)
{
    const uint8_t d[8] = {(uint8_t)code, (uint8_t)(code >> 8), (uint8_t)sim_co_od_get(&n->od, 0x1001u, 0u), 0, 0, 0, 0,
                          0};
    if (n->nmt == SIM_NMT_STATE_STOPPED) return; /* CiA 301: no EMCY in stopped */
    queue(n, COB_EMCY + n->id, d, 8u);
    n->emcy_sent++;
}

/* The objects that mirror the drive's state. */
static void refresh(sim_co_node_t *n)
{
    sim_co_od_set(&n->od, 0x6041u, 0u, (uint32_t)n->power);
    sim_co_od_set(&n->od, 0x6061u, 0u, sim_co_od_get(&n->od, 0x6060u, 0u));
}

/* The mode the drive runs: 0x6061, or 0x6060 in a drive whose file lacks the display. */
static int64_t mode_of(const sim_co_node_t *n)
{
    const uint16_t index = sim_co_od_has(&n->od, 0x6061u, 0u) ? 0x6061u : 0x6060u;
    return sim_co_od_get_signed(&n->od, index, 0u);
}

/* ---- PDOs ---------------------------------------------------------------------------------- */
static void parse_pdo(const sim_co_od_t *od, uint16_t comm, uint16_t map, sim_co_pdo_t *p)
{
    memset(p, 0, sizeof(*p));
    if (!sim_co_od_has(od, comm, 1u)) return; /* a PDO the drive does not have: never valid */
    p->cob_id = (uint32_t)sim_co_od_get(od, comm, 1u);
    p->valid = (p->cob_id & COB_INVALID) == 0u;
    p->trans = (uint8_t)sim_co_od_get(od, comm, 2u);
    const unsigned count = (unsigned)sim_co_od_get(od, map, 0u);
    for (unsigned k = 0; k < count && k < SIM_CO_MAP_MAX; ++k) {
        const uint32_t e = (uint32_t)sim_co_od_get(od, map, (uint8_t)(k + 1u));
        p->index[p->n] = (uint16_t)(e >> 16);
        p->sub[p->n] = (uint8_t)(e >> 8);
        p->bytes[p->n] = (uint8_t)((e & 0xFFu) / 8u);
        p->len += p->bytes[p->n];
        p->n++;
    }
}

static void parse_pdos(sim_co_node_t *n)
{
    for (unsigned k = 0; k < SIM_CO_N_PDO; ++k) {
        parse_pdo(&n->od, (uint16_t)(RPDO_COMM + k), (uint16_t)(RPDO_MAP + k), &n->rpdo[k]);
        parse_pdo(&n->od, (uint16_t)(TPDO_COMM + k), (uint16_t)(TPDO_MAP + k), &n->tpdo[k]);
        n->rpdo_pending[k] = 0;
    }
}

/* A mapping entry (index << 16 | sub << 8 | bits): 0, or why the file says it cannot be mapped:
 * PDOMapping=0, the wrong direction (an RPDO writes its objects, a TPDO reads them; rww maps to
 * RPDOs only, rwr to TPDOs only, a dummy object only pads RPDOs), or not the object's whole size. */
static uint32_t check_entry(const sim_co_od_t *od, uint32_t e, int receive)
{
    if (e == 0u) return 0u;
    uint32_t ab = 0;
    const int i = sim_co_od_find(od, (uint16_t)(e >> 16), (uint8_t)(e >> 8), &ab);
    if (i < 0) return ab;
    const sim_co_entry_t *x = &od->t->e[i];
    const int dummy = x->index >= 1u && x->index <= 7u;
    const int readable = !dummy && x->access != SIM_CO_A_WO && x->access != SIM_CO_A_RWW;
    const int writable = dummy || x->access == SIM_CO_A_RW || x->access == SIM_CO_A_WO || x->access == SIM_CO_A_RWW;
    if (!x->pdo || x->size == 0u || (receive ? !writable : !readable) || (e & 0xFFu) != 8u * x->size) {
        return SIM_CO_ABORT_NOT_MAPPABLE;
    }
    return 0u;
}

/* ---- CiA 402 ------------------------------------------------------------------------------- */
static void set_error(sim_co_node_t *n, uint16_t code, uint8_t reg)
{
    sim_co_od_set(&n->od, 0x603Fu, 0u, code);
    sim_co_od_set(&n->od, 0x1001u, 0u, reg);
}

/* An option code the drive reads (0x605A, 0x605E), or CiA 402's default where its file lacks it. */
static int option_code(const sim_co_node_t *n, uint16_t index, int dflt)
{
    return sim_co_od_has(&n->od, index, 0u) ? (int)sim_co_od_get_signed(&n->od, index, 0u) : dflt;
}

/* A ramp's deceleration at the joint, rad/s^2: 0x6084 (slow down) or 0x6085 (quick stop), in
 * position increments per s^2 (CiA 402's unit without a factor group), else the default. */
static double deceleration(const sim_co_node_t *n, uint16_t index)
{
    if (!sim_co_od_has(&n->od, index, 0u) || sim_co_od_get(&n->od, index, 0u) == 0u) return n->default_decel;
    sim_cia402_scale_t sc;
    if (sim_cia402_scale(&n->od, &n->preset, &sc) != 0 || sc.inc_per_rad <= 0.0) return n->default_decel;
    return (double)sim_co_od_get(&n->od, index, 0u) / sc.inc_per_rad;
}

void sim_co_node_fault(sim_co_node_t *n, uint16_t emcy_code, uint8_t error_register)
{
    if (n->power == SIM_PS_FAULT || n->power == SIM_PS_FAULT_REACTION) return;
    /* a drive without 0x605E takes CiA 402's default, 2: the quick stop ramp */
    sim_power_stage_fault(&n->ps, &n->power, option_code(n, 0x605Eu, SIM_FR_QUICK), deceleration(n, 0x6084u),
                          deceleration(n, 0x6085u));
    set_error(n, emcy_code, (uint8_t)(error_register | ERR_REG_GENERIC));
    refresh(n);
    emcy(n, emcy_code);
}

/* The state machine's next state, through the power stage. */
static void move_to(sim_co_node_t *n, sim_power_t next, int qs)
{
    sim_power_stage_transition(&n->ps, &n->power, next, qs, deceleration(n, 0x6084u), deceleration(n, 0x6085u));
}

static void controlword(sim_co_node_t *n, uint16_t cw)
{
    const sim_power_t before = n->power;
    /* a drive without 0x605A takes CiA 402's default, 2: quick stop, then switch on disabled */
    const int qs = option_code(n, 0x605Au, SIM_QS_QUICK);
    move_to(n, sim_cia402_next(n->power, cw, n->prev_cw, qs), qs);
    n->prev_cw = cw;
    if (before == SIM_PS_FAULT && n->power != SIM_PS_FAULT) { /* fault reset */
        set_error(n, 0u, 0u);
        emcy(n, SIM_CO_EMCY_RESET);
    }
    refresh(n);
}

/* A value written by SDO or RPDO takes effect. */
static void took(sim_co_node_t *n, uint16_t index)
{
    const int64_t now_ns = n->now_ns;
    if (index == 0x6040u) controlword(n, (uint16_t)sim_co_od_get(&n->od, 0x6040u, 0u));
    if (index == 0x6060u) refresh(n);
    if (index == 0x1017u) n->hb_next_ns = now_ns;
    if (index == 0x1016u) n->hbc_armed = 0; /* from the producer's next heartbeat on */
    if ((index >= RPDO_COMM && index < RPDO_COMM + SIM_CO_N_PDO) || (index >= RPDO_MAP && index < RPDO_MAP + SIM_CO_N_PDO) ||
        (index >= TPDO_COMM && index < TPDO_COMM + SIM_CO_N_PDO) || (index >= TPDO_MAP && index < TPDO_MAP + SIM_CO_N_PDO)) {
        parse_pdos(n);
    }
}

/* ---- object dictionary access (SDO) --------------------------------------------------------- */
static int pdo_of(uint16_t index, uint16_t base, unsigned *k)
{
    if (index < base || index >= base + SIM_CO_N_PDO) return 0;
    *k = index - base;
    return 1;
}

static uint32_t check_pdo_write(const sim_co_node_t *n, uint16_t index, uint8_t sub, uint64_t v)
{
    unsigned k = 0;
    const int rcomm = pdo_of(index, RPDO_COMM, &k), tcomm = !rcomm && pdo_of(index, TPDO_COMM, &k);
    if (rcomm || tcomm) {
        const uint32_t cob = (uint32_t)sim_co_od_get(&n->od, index, 1u);
        if (sub == 1u) {
            if ((v & COB_FRAME) != 0u || (v & 0x7FFu) == 0u) return SIM_CO_ABORT_RANGE;
            /* CiA 301: a valid PDO's COB-ID may not change; invalidate it first */
            if ((cob & COB_INVALID) == 0u && (v & COB_INVALID) == 0u && (v & 0x7FFu) != (cob & 0x7FFu)) {
                return SIM_CO_ABORT_RANGE;
            }
        }
        /* CiA 301: 0 acyclic, 1-240 every n-th SYNC, 241-253 reserved, 254/255 event-driven. A TPDO
         * of type 0, 254 or 255 is taken, as the drive's file allows, but not sent: this drive sends
         * its TPDOs on SYNC only */
        if (sub == 2u && v > 240u && v < 254u) return SIM_CO_ABORT_RANGE;
        return 0u;
    }
    const int rmap = pdo_of(index, RPDO_MAP, &k), tmap = !rmap && pdo_of(index, TPDO_MAP, &k);
    if (!rmap && !tmap) return 0u;
    const uint16_t comm = (uint16_t)((rmap ? RPDO_COMM : TPDO_COMM) + k);
    if ((sim_co_od_get(&n->od, comm, 1u) & COB_INVALID) == 0u) return SIM_CO_ABORT_STATE; /* the PDO is valid */
    if (sub != 0u) {
        if (sim_co_od_get(&n->od, index, 0u) != 0u) return SIM_CO_ABORT_STATE; /* count 0 first */
        return check_entry(&n->od, (uint32_t)v, rmap);
    }
    if (v > SIM_CO_MAP_MAX) return SIM_CO_ABORT_PDO_LENGTH; /* more entries than 8 bytes hold */
    unsigned bits = 0;
    for (unsigned s = 1; s <= v; ++s) {
        if (!sim_co_od_has(&n->od, index, (uint8_t)s)) return SIM_CO_ABORT_RANGE; /* the file's mapping is shorter */
        const uint32_t e = (uint32_t)sim_co_od_get(&n->od, index, (uint8_t)s);
        const uint32_t ab = check_entry(&n->od, e, rmap);
        if (ab != 0u) return ab;
        if (e == 0u) return SIM_CO_ABORT_NOT_MAPPABLE;
        bits += e & 0xFFu;
    }
    return bits > 64u ? SIM_CO_ABORT_PDO_LENGTH : 0u;
}

uint32_t sim_co_node_exists(void *node, uint16_t index, uint8_t sub)
{
    const sim_co_node_t *n = node;
    uint32_t ab = 0;
    return sim_co_od_find(&n->od, index, sub, &ab) < 0 ? ab : 0u;
}

uint32_t sim_co_node_read(void *node, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap, unsigned *len)
{
    const sim_co_node_t *n = node;
    return sim_co_od_read(&n->od, index, sub, buf, cap, len);
}

uint32_t sim_co_node_write(void *node, uint16_t index, uint8_t sub, const uint8_t *data, unsigned len)
{
    sim_co_node_t *n = node;
    uint64_t v = 0;
    int string = 0;
    uint32_t ab = sim_co_od_check_write(&n->od, index, sub, data, len, &v, &string);
    if (ab != 0u || string) return ab; /* a string is stored as it came: no drive behaviour hangs on one */
    ab = check_pdo_write(n, index, sub, v);
    const int scaling = index == 0x6076u || index == 0x608Fu || index == 0x6091u;
    if (ab == 0u && index == 0x6060u && !sim_cia402_mode_supported(&n->od, (int8_t)(uint8_t)v)) ab = SIM_CO_ABORT_RANGE;
    if (ab == 0u && scaling && sub <= 2u && v == 0u && (index == 0x6076u || sub >= 1u)) {
        ab = SIM_CO_ABORT_RANGE; /* a unit of 0 would divide by it */
    }
    if (ab == 0u && (scaling || index == 0x6060u) && sim_power_stage_energised(&n->ps)) {
        ab = SIM_CO_ABORT_STATE; /* no new scaling or mode while torque flows */
    }
    if (ab != 0u) return ab;
    sim_co_od_set(&n->od, index, sub, v);
    took(n, index);
    return 0u;
}

/* ---- NMT ----------------------------------------------------------------------------------- */
static void apply_presets(sim_co_node_t *n)
{
    const sim_co_preset_t *p = &n->preset;
    if (p->rated_torque_mnm) sim_co_od_set(&n->od, 0x6076u, 0u, p->rated_torque_mnm);
    if (p->encoder_increments) sim_co_od_set(&n->od, 0x608Fu, 1u, p->encoder_increments);
    if (p->gear_motor) sim_co_od_set(&n->od, 0x6091u, 1u, p->gear_motor);
    if (p->gear_shaft) sim_co_od_set(&n->od, 0x6091u, 2u, p->gear_shaft);
    if (p->quick_stop_decel) sim_co_od_set(&n->od, 0x6085u, 0u, p->quick_stop_decel);
    if (p->max_torque_permille) sim_co_od_set(&n->od, 0x6072u, 0u, p->max_torque_permille);
}

static void boot(sim_co_node_t *n, int64_t now_ns, int comm_only)
{
    n->now_ns = now_ns;
    sim_co_od_reset(&n->od, n->table, n->id, comm_only);
    /* each drive its own serial number, after either reset: 0x1018 is in the communication area */
    sim_co_od_set(&n->od, 0x1018u, 4u, n->id);
    if (!comm_only) {
        apply_presets(n);
        if (sim_power_stage_energised(&n->ps)) { /* a reset of a running drive: the power stage off, the brake closing */
            sim_power_stage_power_lost(&n->ps, &n->power);
        }
        n->power = SIM_PS_SWITCH_ON_DISABLED; /* not ready to switch on passes at once: no self-test */
        n->prev_cw = 0u;
    }
    sim_co_sdo_init(&n->sdo);
    parse_pdos(n);
    refresh(n);
    n->hbc_armed = 0;
    n->nmt = SIM_NMT_STATE_BOOT;
    heartbeat(n); /* boot-up */
    n->nmt = SIM_NMT_STATE_PRE_OPERATIONAL;
    n->hb_next_ns = now_ns;
    memset(n->tpdo_syncs, 0, sizeof(n->tpdo_syncs));
}

void sim_co_node_set_stopping(sim_co_node_t *n, const sim_brake_config_t *brake, double joint_inertia,
                              double default_decel)
{
    n->brake = *brake;
    n->joint_inertia = joint_inertia;
    n->default_decel = default_decel;
    sim_power_stage_init(&n->ps, brake, n->limit_nm, joint_inertia);
}

int sim_co_node_init(sim_co_node_t *n, const sim_co_table_t *table, uint8_t id, const sim_co_preset_t *preset,
                     double limit_nm, double overcurrent_at_s, char *err, unsigned long errcap)
{
    memset(n, 0, sizeof(*n));
    const sim_brake_config_t none = {0.0, 0.0, 0.0};
    n->limit_nm = limit_nm;
    sim_co_node_set_stopping(n, &none, 0.0, 0.0);
    n->table = table;
    n->id = id;
    n->preset = *preset;
    n->limit_nm = limit_nm;
    n->overcurrent_at_s = overcurrent_at_s;
    static const uint16_t needed[] = {0x6040u, 0x6041u};
    for (unsigned k = 0; k < sizeof(needed) / sizeof(needed[0]); ++k) {
        uint32_t ab = 0;
        if (sim_co_table_find(table, needed[k], 0u, &ab) < 0) {
            snprintf(err, errcap, "node %u: the drive's file has no 0x%04X (CiA 402 %s): not a drive this simulator "
                     "can emulate", id, needed[k], k == 0u ? "controlword" : "statusword");
            return -1;
        }
    }
    sim_co_od_reset(&n->od, table, id, 0);
    apply_presets(n);
    sim_cia402_scale_t sc;
    if (sim_cia402_scale(&n->od, preset, &sc) != 0) {
        snprintf(err, errcap, "node %u: no units: the drive's file lacks 0x608F, 0x6091 or 0x6076 (or holds 0) and the "
                 "drive table (--node ID,encoder=,gear=,rated=) gives none", id);
        return -1;
    }
    return 0;
}

void sim_co_node_boot(sim_co_node_t *n, int64_t now_ns)
{
    boot(n, now_ns, 0);
}

static void on_nmt(sim_co_node_t *n, uint8_t cmd, int64_t now_ns)
{
    /* leaving operational while energised: CiA 402's abort connection, here a quick stop */
    if ((cmd == SIM_NMT_STOP || cmd == NMT_PRE_OPERATIONAL) && n->power == SIM_PS_OPERATION_ENABLED) {
        move_to(n, SIM_PS_QUICK_STOP_ACTIVE, SIM_QS_QUICK);
        refresh(n);
    }
    switch (cmd) {
    case SIM_NMT_START: /* a TPDO of type n goes at every n-th SYNC counted from here (a restarted master's too) */
        if (n->nmt != SIM_NMT_STATE_OPERATIONAL) memset(n->tpdo_syncs, 0, sizeof(n->tpdo_syncs));
        n->nmt = SIM_NMT_STATE_OPERATIONAL;
        break;
    case SIM_NMT_STOP: n->nmt = SIM_NMT_STATE_STOPPED; break;
    case NMT_PRE_OPERATIONAL: n->nmt = SIM_NMT_STATE_PRE_OPERATIONAL; break;
    case NMT_RESET_NODE: boot(n, now_ns, 0); break;
    case NMT_RESET_COMM: boot(n, now_ns, 1); break;
    default: break;
    }
}

int sim_co_node_sends(const sim_co_node_t *n, uint32_t id)
{
    if (id == COB_EMCY + n->id || id == COB_SDO_TX + n->id || id == COB_HEARTBEAT + n->id) return 1;
    for (unsigned k = 0; k < SIM_CO_N_PDO; ++k) {
        if (n->tpdo[k].valid && (n->tpdo[k].cob_id & 0x7FFu) == id) return 1;
    }
    return 0;
}

static void apply_rpdo(sim_co_node_t *n, unsigned k)
{
    const sim_co_pdo_t *p = &n->rpdo[k];
    unsigned off = 0;
    for (unsigned e = 0; e < p->n; ++e) {
        uint32_t v = 0;
        for (unsigned b = 0; b < p->bytes[e]; ++b) v |= (uint32_t)n->rpdo_data[k][off + b] << (8u * b);
        off += p->bytes[e];
        if (p->index[e] == 0x6060u && !sim_cia402_mode_supported(&n->od, (int8_t)(uint8_t)v)) continue;
        sim_co_od_set(&n->od, p->index[e], p->sub[e], v);
        took(n, p->index[e]);
    }
    n->rpdo_pending[k] = 0;
}

void sim_co_node_on_frame(sim_co_node_t *n, const arm_can_frame_t *f, int64_t now_ns)
{
    n->now_ns = now_ns;
    if (f->id == COB_NMT) {
        if (f->len == 2u && (f->data[1] == 0u || f->data[1] == n->id)) on_nmt(n, f->data[0], now_ns);
        return;
    }
    const uint32_t hbc = (uint32_t)sim_co_od_get(&n->od, 0x1016u, 1u);
    const uint32_t producer = (hbc >> 16) & 0x7Fu;
    if (producer != 0u && f->id == COB_HEARTBEAT + producer && f->len >= 1u) {
        n->hbc_last_ns = now_ns;
        n->hbc_armed = (hbc & 0xFFFFu) != 0u;
        return;
    }
    if (n->nmt == SIM_NMT_STATE_STOPPED) return; /* only NMT and heartbeats in stopped */
    if (f->id == COB_SDO_RX + n->id) {
        const sim_co_sdo_access_t a = {sim_co_node_read, sim_co_node_write, sim_co_node_exists, n};
        uint8_t resp[8];
        if (sim_co_sdo_on_request(&n->sdo, &a, f->data, f->len, resp)) queue(n, COB_SDO_TX + n->id, resp, 8u);
        return;
    }
    if (n->nmt != SIM_NMT_STATE_OPERATIONAL) return;
    for (unsigned k = 0; k < SIM_CO_N_PDO; ++k) {
        const sim_co_pdo_t *p = &n->rpdo[k];
        if (!p->valid || (p->cob_id & 0x7FFu) != f->id) continue;
        n->pdo_rx++;
        if (f->len < p->len) { /* CiA 301: not processed (a real drive may send EMCY 0x8210) */
            n->pdo_rx_short++;
            return;
        }
        memcpy(n->rpdo_data[k], f->data, 8u);
        n->rpdo_pending[k] = 1;
        if (p->trans >= 254u) apply_rpdo(n, k); /* event-driven: at once */
    }
}

void sim_co_node_on_sync(sim_co_node_t *n, double q, double qd, double tau_measured)
{
    if (n->nmt != SIM_NMT_STATE_OPERATIONAL) return;
    for (unsigned k = 0; k < SIM_CO_N_PDO; ++k) {
        if (n->rpdo_pending[k]) apply_rpdo(n, k);
    }
    sim_cia402_scale_t sc;
    (void)sim_cia402_scale(&n->od, &n->preset, &sc);
    /* torque actual: the target it follows, its own ramp's, or none */
    const double own = n->ps.mode == SIM_STAGE_FOLLOW ? sim_co_node_torque(n) : n->ps.mode == SIM_STAGE_RAMP ? n->ps.last_nm : 0.0;
    const double tau = isnan(tau_measured) ? own : tau_measured;
    sim_co_od_set(&n->od, 0x6064u, 0u, (uint32_t)sim_cia402_increments(&sc, q));
    sim_co_od_set(&n->od, 0x606Cu, 0u, (uint32_t)sim_cia402_increments(&sc, qd));
    sim_co_od_set(&n->od, 0x6077u, 0u, (uint32_t)(uint16_t)sim_cia402_permille(&sc, tau));
    for (unsigned k = 0; k < SIM_CO_N_PDO; ++k) {
        const sim_co_pdo_t *p = &n->tpdo[k];
        if (!p->valid || p->trans == 0u || p->trans > 240u) continue;
        if (++n->tpdo_syncs[k] < p->trans) continue;
        n->tpdo_syncs[k] = 0u;
        uint8_t d[8] = {0};
        unsigned off = 0;
        for (unsigned e = 0; e < p->n; ++e) {
            const uint64_t v = sim_co_od_get(&n->od, p->index[e], p->sub[e]);
            for (unsigned b = 0; b < p->bytes[e]; ++b) d[off + b] = (uint8_t)(v >> (8u * b));
            off += p->bytes[e];
        }
        queue(n, p->cob_id & 0x7FFu, d, p->len);
    }
}

void sim_co_node_tick(sim_co_node_t *n, int64_t now_ns, double sim_s)
{
    n->now_ns = now_ns;
    const uint32_t hb_ms = (uint32_t)sim_co_od_get(&n->od, 0x1017u, 0u);
    if (hb_ms != 0u && now_ns >= n->hb_next_ns) {
        heartbeat(n);
        n->hb_next_ns += (int64_t)hb_ms * 1000000;
        if (n->hb_next_ns < now_ns) n->hb_next_ns = now_ns + (int64_t)hb_ms * 1000000; /* no burst after a stall */
    }
    const uint32_t hbc_ms = (uint32_t)sim_co_od_get(&n->od, 0x1016u, 1u) & 0xFFFFu;
    if (n->hbc_armed && hbc_ms != 0u && now_ns - n->hbc_last_ns > (int64_t)hbc_ms * 1000000) {
        n->hbc_armed = 0; /* monitoring resumes with the producer's next heartbeat */
        /* CiA 402's reaction to a lost master (0x6007) is for a drive that applies torque: one the
         * master stopped and disabled before it left has nothing to stop, and is not faulted (the
         * next master boots it as it is) */
        if (n->power == SIM_PS_OPERATION_ENABLED || n->power == SIM_PS_QUICK_STOP_ACTIVE) {
            sim_co_node_fault(n, SIM_CO_EMCY_HEARTBEAT, ERR_REG_COMMUNICATION);
        }
    }
    if (n->overcurrent_at_s >= 0.0 && !n->overcurrent_done && sim_s >= n->overcurrent_at_s &&
        n->power == SIM_PS_OPERATION_ENABLED) { /* a current flows only when enabled */
        n->overcurrent_done = 1;
        sim_co_node_fault(n, SIM_CO_EMCY_OVERCURRENT, ERR_REG_CURRENT);
    }
}

int64_t sim_co_node_wait_ns(const sim_co_node_t *n, int64_t now_ns)
{
    int64_t w = 50000000; /* 50 ms: the overcurrent hook and timers are checked at least this often */
    if (sim_co_od_get(&n->od, 0x1017u, 0u) != 0u && n->hb_next_ns - now_ns < w) w = n->hb_next_ns - now_ns;
    const uint32_t hbc_ms = (uint32_t)sim_co_od_get(&n->od, 0x1016u, 1u) & 0xFFFFu;
    if (n->hbc_armed && hbc_ms != 0u) {
        const int64_t left = n->hbc_last_ns + (int64_t)hbc_ms * 1000000 + 1000000 - now_ns;
        if (left < w) w = left;
    }
    return w < 0 ? 0 : w;
}

/* The target torque the master sends (CST, NMT operational), whatever the power state. */
static double target_nm(const sim_co_node_t *n)
{
    if (n->nmt != SIM_NMT_STATE_OPERATIONAL || mode_of(n) != SIM_CIA402_MODE_CST) return 0.0;
    sim_cia402_scale_t sc;
    (void)sim_cia402_scale(&n->od, &n->preset, &sc);
    /* without 0x6072 (max torque) the drive limits nothing but the joint's own torque */
    const uint32_t max = sim_co_od_has(&n->od, 0x6072u, 0u) ? (uint32_t)sim_co_od_get(&n->od, 0x6072u, 0u) : 32767u;
    return sim_cia402_target_nm(&sc, (int32_t)sim_co_od_get_signed(&n->od, 0x6071u, 0u), max, n->limit_nm);
}

double sim_co_node_period(sim_co_node_t *n, double qd, double dt)
{
    const sim_power_t before = n->power;
    const double tau = sim_power_stage_period(&n->ps, &n->power, target_nm(n), qd, dt);
    if (n->power != before) refresh(n); /* the brake closed: the state held back is reported */
    return tau;
}

void sim_co_node_power_lost(sim_co_node_t *n)
{
    sim_power_stage_power_lost(&n->ps, &n->power);
}

double sim_co_node_torque(const sim_co_node_t *n)
{
    /* another mode the drive offers is taken, but this emulation moves only in CST */
    return n->power == SIM_PS_OPERATION_ENABLED ? target_nm(n) : 0.0;
}
