/* The emulated CANopen drive without a bus: its object dictionary (from the EDS), the SDO server's
 * transfers and abort codes, the PDO rules of CiA 301 and the CiA 402 behaviour. */
#include <math.h>
#include <string.h>

#include "check.h"
#include "sim_canopen_node.h"

#define MS 1000000LL

/* Node id, on the build's own drive's dictionary (cia402_servo.eds): 0, or -1 with err. */
static int init(sim_co_node_t *n, uint8_t id, const sim_co_preset_t *preset, double limit_nm)
{
    char err[300];
    const sim_co_table_t *t = sim_co_table_builtin();
    CHECK(t != NULL);
    return t == NULL ? -1 : sim_co_node_init(n, t, id, preset, limit_nm, -1.0, err, sizeof(err));
}

static sim_co_node_t node(void)
{
    sim_co_node_t n;
    const sim_co_preset_t none = {0};
    CHECK(init(&n, 3, &none, 150.0) == 0);
    sim_co_node_boot(&n, 0);
    return n;
}

static void frame(sim_co_node_t *n, uint32_t id, const uint8_t *d, unsigned len, int64_t t)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.len = (uint8_t)len;
    memcpy(f.data, d, len);
    n->n_out = 0u;
    sim_co_node_on_frame(n, &f, t);
}

/* One SDO request; the response's 8 bytes (all 0xEE if none came). */
static const uint8_t *sdo(sim_co_node_t *n, uint8_t b0, uint16_t index, uint8_t sub, uint32_t v)
{
    static uint8_t resp[8];
    const uint8_t d[8] = {b0, (uint8_t)index, (uint8_t)(index >> 8), sub, (uint8_t)v, (uint8_t)(v >> 8),
                          (uint8_t)(v >> 16), (uint8_t)(v >> 24)};
    frame(n, 0x600u + n->id, d, 8u, 0);
    memset(resp, 0xEE, sizeof(resp));
    if (n->n_out == 1u && n->out[0].id == 0x580u + n->id) memcpy(resp, n->out[0].data, 8);
    return resp;
}

static uint32_t u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint32_t abort_of(const uint8_t *r)
{
    return r[0] == 0x80u ? u32(&r[4]) : 0u;
}

static uint32_t write(sim_co_node_t *n, uint16_t index, uint8_t sub, uint32_t v, unsigned size)
{
    return abort_of(sdo(n, (uint8_t)(0x23u | ((4u - size) << 2)), index, sub, v));
}

static void boot_up_and_defaults(void)
{
    sim_co_node_t n;
    const sim_co_preset_t none = {0};
    CHECK(init(&n, 3, &none, 150.0) == 0);
    sim_co_node_boot(&n, 0);
    CHECK(n.n_out == 1u && n.out[0].id == 0x703u && n.out[0].len == 1u && n.out[0].data[0] == 0x00u);
    CHECK(n.nmt == SIM_NMT_STATE_PRE_OPERATIONAL);
    CHECK(sim_co_od_get(&n.od, 0x1400u, 1u) == 0x203u);              /* $NODEID+0x200 */
    CHECK(sim_co_od_get(&n.od, 0x1401u, 1u) == 0x80000303u);         /* RPDO2 invalid */
    CHECK(sim_co_od_get(&n.od, 0x6076u, 0u) == 1486u); /* the motor's, mN m */
    CHECK(sim_co_od_get(&n.od, 0x608Fu, 1u) == 524288u && sim_co_od_get(&n.od, 0x6091u, 1u) == 101u);
    const sim_co_preset_t p = {560u, 4096u, 50u, 1u, 0u, 0.0, 0u, 0u};
    CHECK(init(&n, 3, &p, 28.0) == 0);
    sim_co_node_boot(&n, 0);
    CHECK(sim_co_od_get(&n.od, 0x6076u, 0u) == 560u && sim_co_od_get(&n.od, 0x608Fu, 1u) == 4096u);
    CHECK(sim_co_od_get(&n.od, 0x6091u, 1u) == 50u);
}

/* CiA 402: 0x6076 is the motor's; the joint gets per-mille x 0x6076 x gear x the gear's efficiency,
 * and a joint torque is reported back through the same. */
static void torque_through_the_gear(void)
{
    sim_co_node_t n;
    const sim_co_preset_t p = {0u, 0u, 0u, 0u, 0u, 0.8, 0u, 0u};
    CHECK(init(&n, 3, &p, 150.0) == 0);
    sim_cia402_scale_t sc;
    CHECK(sim_cia402_scale(&n.od, &n.preset, &sc) == 0);
    CHECK(fabs(sc.joint_rated_nm - 1.486 * 101.0 * 0.8) < 1e-12);
    CHECK(fabs(sim_cia402_target_nm(&sc, 100, 1000u, 150.0) - 0.1 * 1.486 * 101.0 * 0.8) < 1e-12);
    CHECK(sim_cia402_permille(&sc, 0.1 * 1.486 * 101.0 * 0.8) == 100);
    const sim_co_preset_t bad = {0u, 0u, 0u, 0u, 0u, 1.5, 0u, 0u}; /* an efficiency above 1: no units */
    CHECK(sim_cia402_scale(&n.od, &bad, &sc) == -1);
}

static void expedited_and_segmented_uploads(void)
{
    sim_co_node_t n = node();
    const uint8_t *r = sdo(&n, 0x40, 0x1000, 0, 0);
    CHECK(r[0] == 0x43u && r[1] == 0x00u && r[2] == 0x10u && u32(&r[4]) == 0x00020192u);
    r = sdo(&n, 0x40, 0x1001, 0, 0);
    CHECK(r[0] == 0x4Fu); /* one byte: n = 3 */
    r = sdo(&n, 0x40, 0x1008, 0, 0);
    const char *name = "Arm emulated CiA 402 servo drive";
    CHECK(r[0] == 0x41u && u32(&r[4]) == strlen(name));
    char got[64] = {0};
    unsigned len = 0, last = 0;
    for (uint8_t t = 0; !last && len < 60u; t ^= 1u) {
        r = sdo(&n, (uint8_t)(0x60u | ((unsigned)t << 4)), 0, 0, 0);
        CHECK((r[0] & 0xE0u) == 0x00u && ((r[0] >> 4) & 1u) == (unsigned)t);
        const unsigned k = 7u - ((r[0] >> 1) & 7u);
        memcpy(&got[len], &r[1], k);
        len += k;
        last = r[0] & 1u;
    }
    CHECK(strcmp(got, name) == 0);
    sdo(&n, 0x40, 0x1008, 0, 0);
    r = sdo(&n, 0x70, 0, 0, 0); /* toggle 1 first: not alternated */
    CHECK(abort_of(r) == 0x05030000u);
    CHECK(abort_of(sdo(&n, 0x60, 0, 0, 0)) == 0x05040001u); /* a segment with no transfer */
    CHECK(abort_of(sdo(&n, 0xA0, 0x1000, 0, 0)) == 0x05040001u); /* block upload: not supported */
}

static void downloads_and_abort_codes(void)
{
    sim_co_node_t n = node();
    CHECK(write(&n, 0x1017, 0, 100u, 2u) == 0u && sim_co_od_get(&n.od, 0x1017u, 0u) == 100u);
    CHECK(write(&n, 0x1000, 0, 1u, 4u) == 0x06010002u);
    CHECK(write(&n, 0x2000, 0, 1u, 4u) == 0x06020000u);
    CHECK(write(&n, 0x1018, 7, 1u, 4u) == 0x06090011u);
    CHECK(write(&n, 0x6040, 0, 1u, 4u) == 0x06070010u);
    CHECK(write(&n, 0x6060, 0, 3u, 1u) == 0x06090030u);
    CHECK(write(&n, 0x6060, 0, 8u, 1u) == 0x06090030u); /* CSP is not offered */
    CHECK(write(&n, 0x6076, 0, 0u, 4u) == 0x06090030u); /* a rated torque of 0 would divide by it */
    CHECK(write(&n, 0x6060, 0, 10u, 1u) == 0u && sim_co_od_get_signed(&n.od, 0x6061u, 0u) == 10);
    /* size not indicated (0x22): the object's own length */
    CHECK(abort_of(sdo(&n, 0x22, 0x6072, 0, 500u)) == 0u && sim_co_od_get(&n.od, 0x6072u, 0u) == 500u);
    /* segmented download of 0x1006 (4 bytes in one segment) */
    const uint8_t *r = sdo(&n, 0x21, 0x1006, 0, 4u);
    CHECK(r[0] == 0x60u);
    const uint8_t seg[8] = {0x00u | (3u << 1) | 1u, 0x10, 0x27, 0x00, 0x00, 0, 0, 0};
    frame(&n, 0x603u, seg, 8u, 0);
    CHECK(n.n_out == 1u && n.out[0].data[0] == 0x20u && sim_co_od_get(&n.od, 0x1006u, 0u) == 10000u);
    CHECK(abort_of(sdo(&n, 0x40, 0x1008, 0, 0)) == 0u); /* the server is idle again */
    uint8_t shortreq[4] = {0x40, 0x00, 0x10, 0x00};
    frame(&n, 0x603u, shortreq, 4u, 0);
    CHECK(n.n_out == 1u && abort_of(n.out[0].data) == 0x05040001u);
}

static void mapping_rules(void)
{
    sim_co_node_t n = node();
    CHECK(write(&n, 0x1A00, 0, 0u, 1u) == 0x08000022u);          /* TPDO1 valid */
    CHECK(write(&n, 0x1A00, 1, 0x60410010u, 4u) == 0x08000022u);
    CHECK(write(&n, 0x1800, 1, 0x190u, 4u) == 0x06090030u);      /* a valid PDO's COB-ID stays */
    CHECK(write(&n, 0x1800, 1, 0x80000183u, 4u) == 0u);
    CHECK(write(&n, 0x1A00, 1, 0x60410010u, 4u) == 0x08000022u); /* count first */
    CHECK(write(&n, 0x1A00, 0, 0u, 1u) == 0u);
    CHECK(write(&n, 0x1A00, 1, 0x60760020u, 4u) == 0x06040041u); /* 0x6076: not mappable */
    CHECK(write(&n, 0x1A00, 1, 0x60410020u, 4u) == 0x06040041u); /* wrong length */
    CHECK(write(&n, 0x1A00, 1, 0x60640020u, 4u) == 0u);
    CHECK(write(&n, 0x1A00, 2, 0x606C0020u, 4u) == 0u);
    CHECK(write(&n, 0x1A00, 3, 0x60410010u, 4u) == 0u);
    CHECK(write(&n, 0x1A00, 0, 3u, 1u) == 0x06040042u);          /* 80 bits */
    CHECK(write(&n, 0x1A00, 0, 9u, 1u) == 0x06090030u);
    CHECK(write(&n, 0x1A00, 1, 0x60410010u, 4u) == 0u);
    CHECK(write(&n, 0x1A00, 0, 1u, 1u) == 0u);
    CHECK(write(&n, 0x1800, 2, 0xF1u, 1u) == 0x06090030u);      /* 241-253: reserved */
    CHECK(write(&n, 0x1800, 2, 0xFFu, 1u) == 0u);               /* event-driven: taken (sent on SYNC only) */
    CHECK(write(&n, 0x1800, 2, 1u, 1u) == 0u);
    CHECK(write(&n, 0x1800, 1, 0x183u, 4u) == 0u);
    CHECK(n.tpdo[0].valid && n.tpdo[0].n == 1u && n.tpdo[0].len == 2u);
    CHECK(write(&n, 0x1600, 1, 0x60410010u, 4u) == 0x08000022u); /* RPDO1 valid */
}

static unsigned sent(const sim_co_node_t *n, uint32_t id, const arm_can_frame_t **f)
{
    unsigned k = 0;
    for (unsigned i = 0; i < n->n_out; ++i) {
        if (n->out[i].id == id) {
            *f = &n->out[i];
            k++;
        }
    }
    return k;
}

static void rpdo(sim_co_node_t *n, uint16_t cw, int16_t torque)
{
    const uint8_t d[4] = {(uint8_t)cw, (uint8_t)(cw >> 8), (uint8_t)torque, (uint8_t)((uint16_t)torque >> 8)};
    frame(n, 0x203u, d, 4u, 0);
}

static void sync_pdos_and_cst(void)
{
    sim_co_node_t n = node();
    const arm_can_frame_t *f = NULL;
    rpdo(&n, 0x06, 0);
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(n.power == SIM_PS_SWITCH_ON_DISABLED && n.n_out == 0u); /* no PDOs before NMT start */
    const uint8_t start[2] = {0x01, 0x00};
    frame(&n, 0x000u, start, 2u, 0);
    CHECK(n.nmt == SIM_NMT_STATE_OPERATIONAL);
    CHECK(write(&n, 0x6060, 0, 10u, 1u) == 0u);
    rpdo(&n, 0x06, 0);
    CHECK(n.power == SIM_PS_SWITCH_ON_DISABLED); /* synchronous: waits for the SYNC */
    n.n_out = 0u;
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(n.power == SIM_PS_READY_TO_SWITCH_ON);
    CHECK(sent(&n, 0x283u, &f) == 1u && f->len == 4u && (f->data[2] & 0x6Fu) == 0x21u);
    rpdo(&n, 0x07, 0);
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    rpdo(&n, 0x0F, 200);
    n.n_out = 0u;
    sim_co_node_on_sync(&n, 1.0, -0.5, NAN);
    CHECK(n.power == SIM_PS_OPERATION_ENABLED);
    /* 200 per-mille of the motor's 1486 mN m: the joint feels it times the gear, 101 */
    CHECK(fabs(sim_co_node_torque(&n) - 0.2 * 1.486 * 101.0) < 1e-12);
    CHECK(sent(&n, 0x283u, &f) == 1u && (int16_t)(f->data[0] | f->data[1] << 8) == 200);
    CHECK(sent(&n, 0x183u, &f) == 1u && f->len == 8u);
    const double inc_per_rad = 524288.0 * 101.0 / 6.283185307179586;
    CHECK((int32_t)u32(&f->data[0]) == (int32_t)nearbyint(inc_per_rad));
    CHECK((int32_t)u32(&f->data[4]) == (int32_t)nearbyint(-0.5 * inc_per_rad));
    n.n_out = 0u; /* a joint torque measured is reported in per-mille of the motor's, through the gear */
    sim_co_node_on_sync(&n, 0.0, 0.0, 0.1 * 1.486 * 101.0);
    CHECK(sent(&n, 0x283u, &f) == 1u && (int16_t)(f->data[0] | f->data[1] << 8) == 100);
    rpdo(&n, 0x0F, 2000); /* beyond max torque (1000 per-mille, 150.086 N m) and the joint's 150 N m */
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(fabs(sim_co_node_torque(&n) - 150.0) < 1e-12);
    CHECK(write(&n, 0x6076, 0, 1000u, 4u) == 0x08000022u); /* no new scaling while enabled */
    rpdo(&n, 0x02, 200); /* quick stop: 0x605A's default (6) stays in quick stop active, its target no longer applied */
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(n.power == SIM_PS_QUICK_STOP_ACTIVE && sim_co_node_torque(&n) == 0.0);
    for (int k = 0; k < 50; ++k) sim_co_node_period(&n, 0.0, 0.001);
    CHECK(n.power == SIM_PS_QUICK_STOP_ACTIVE); /* holding at standstill until told */
    rpdo(&n, 0x0F, 200); /* enable operation: back (transition 16) */
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(n.power == SIM_PS_OPERATION_ENABLED);
    CHECK(write(&n, 0x605A, 0, 2u, 2u) == 0u); /* 1-4: a quick stop ends in switch on disabled, after its ramp */
    rpdo(&n, 0x02, 200);
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(n.power == SIM_PS_QUICK_STOP_ACTIVE);
    for (int k = 0; k < 50; ++k) sim_co_node_period(&n, 0.0, 0.001);
    CHECK(n.power == SIM_PS_SWITCH_ON_DISABLED && sim_co_node_torque(&n) == 0.0);
    CHECK(sim_co_od_get(&n.od, 0x6041u, 0u) == SIM_PS_SWITCH_ON_DISABLED); /* reported once reached */
    CHECK(write(&n, 0x605A, 0, 9u, 2u) == 0x06090030u); /* beyond the EDS's range */
}

static void heartbeat_consumer_faults(void)
{
    sim_co_node_t n = node();
    CHECK(write(&n, 0x1016, 1, 0x7Fu << 16 | 100u, 4u) == 0u);
    const uint8_t start[2] = {0x01, 0x03};
    frame(&n, 0x000u, start, 2u, 0);
    const uint8_t op = 0x05;
    frame(&n, 0x77Fu, &op, 1u, 0);
    n.n_out = 0u;
    /* a drive the master disabled before it left has nothing to stop: not faulted */
    sim_co_node_tick(&n, 101 * MS, 0.0);
    CHECK(n.power == SIM_PS_SWITCH_ON_DISABLED && n.n_out == 0u);
    /* one that applies torque is (CiA 402's reaction to a lost master) */
    CHECK(write(&n, 0x6060, 0, 10u, 1u) == 0u);
    const uint16_t steps[3] = {0x06, 0x07, 0x0F};
    for (int i = 0; i < 3; ++i) {
        rpdo(&n, steps[i], 0);
        sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    }
    CHECK(n.power == SIM_PS_OPERATION_ENABLED);
    frame(&n, 0x77Fu, &op, 1u, 200 * MS);
    n.n_out = 0u;
    sim_co_node_tick(&n, 290 * MS, 0.0);
    CHECK(n.power != SIM_PS_FAULT);
    sim_co_node_tick(&n, 301 * MS, 0.0);
    const arm_can_frame_t *f = NULL;
    /* an enabled drive: its fault reaction (the ramp to standstill, the brake) before it reports fault */
    CHECK((n.power == SIM_PS_FAULT_REACTION || n.power == SIM_PS_FAULT) && sent(&n, 0x083u, &f) == 1u);
    CHECK(f != NULL && f->data[0] == 0x30u && f->data[1] == 0x81u && (f->data[2] & 0x11u) == 0x11u);
    CHECK(sim_co_od_get(&n.od, 0x603Fu, 0u) == 0x8130u);
    for (int k = 0; k < 5000 && n.power != SIM_PS_FAULT; ++k) (void)sim_co_node_period(&n, 0.0, 0.001);
    CHECK(n.power == SIM_PS_FAULT);
    rpdo(&n, 0x80, 0); /* fault reset */
    n.n_out = 0u;
    sim_co_node_on_sync(&n, 0.0, 0.0, NAN);
    CHECK(n.power == SIM_PS_SWITCH_ON_DISABLED && sent(&n, 0x083u, &f) == 1u && f->data[0] == 0u && f->data[1] == 0u);
}

static void heartbeat_producer_and_resets(void)
{
    sim_co_node_t n = node();
    CHECK(write(&n, 0x1017, 0, 50u, 2u) == 0u);
    CHECK(write(&n, 0x6076, 0, 1000u, 4u) == 0u);
    const arm_can_frame_t *f = NULL;
    n.n_out = 0u;
    sim_co_node_tick(&n, 0, 0.0);
    CHECK(sent(&n, 0x703u, &f) == 1u && f->data[0] == 0x7Fu);
    n.n_out = 0u;
    sim_co_node_tick(&n, 49 * MS, 0.0);
    CHECK(n.n_out == 0u);
    const uint8_t reset_comm[2] = {0x82, 0x03};
    frame(&n, 0x000u, reset_comm, 2u, 0);
    CHECK(sent(&n, 0x703u, &f) == 1u && f->data[0] == 0x00u); /* boot-up */
    CHECK(sim_co_od_get(&n.od, 0x1017u, 0u) == 0u && sim_co_od_get(&n.od, 0x6076u, 0u) == 1000u);
    CHECK(sim_co_od_get(&n.od, 0x1018u, 4u) == 3u); /* the serial number is the drive's own after it */
    const uint8_t reset_node[2] = {0x81, 0x00};
    frame(&n, 0x000u, reset_node, 2u, 0);
    CHECK(sim_co_od_get(&n.od, 0x6076u, 0u) == 1486u);
    const uint8_t stop[2] = {0x02, 0x03};
    frame(&n, 0x000u, stop, 2u, 0);
    CHECK(sdo(&n, 0x40, 0x1000, 0, 0)[0] == 0xEEu); /* no SDO in stopped */
}

/* Any frame on the drive's ids, in any order: under the sanitizers nothing is read or written out
 * of bounds, every SDO request gets at most one answer, the state stays one the drive has. */
static void arbitrary_frames_are_handled(void)
{
    sim_co_node_t n = node();
    uint64_t x = 0x9E3779B97F4A7C15ull;
    const uint32_t ids[] = {0x000u, 0x203u, 0x303u, 0x603u, 0x77Fu};
    int ok = 1;
    for (int i = 0; i < 200000; ++i) {
        uint8_t d[8];
        for (unsigned k = 0; k < 8u; ++k) {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            d[k] = (uint8_t)x;
        }
        const uint32_t id = ids[x % 5u];
        if (id == 0x000u && d[0] >= 0x80u && (i % 64) != 0) continue; /* resets: now and then */
        frame(&n, id, d, (unsigned)((x >> 8) % 9u), (int64_t)i * MS);
        if (id == 0x603u) ok &= n.n_out <= 1u;
        if ((i & 7) == 0) sim_co_node_on_sync(&n, 0.1, 0.0, NAN);
        sim_co_node_tick(&n, (int64_t)i * MS, (double)i * 1e-3);
        ok &= n.power == SIM_PS_SWITCH_ON_DISABLED || n.power == SIM_PS_READY_TO_SWITCH_ON ||
              n.power == SIM_PS_SWITCHED_ON || n.power == SIM_PS_OPERATION_ENABLED || n.power == SIM_PS_FAULT;
        ok &= isfinite(sim_co_node_torque(&n)) && fabs(sim_co_node_torque(&n)) <= 150.0;
    }
    CHECK(ok);
    CHECK(n.sdo.aborts_sent > 0u);
}

int main(void)
{
    torque_through_the_gear();
    boot_up_and_defaults();
    expedited_and_segmented_uploads();
    downloads_and_abort_codes();
    mapping_rules();
    sync_pdos_and_cst();
    heartbeat_consumer_faults();
    heartbeat_producer_and_resets();
    arbitrary_frames_are_handled();
    TEST_MAIN_END();
}
