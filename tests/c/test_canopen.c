/* The CANopen master's portable parts (firmware/canopen): the SDO client's segmented transfers,
 * aborts and retries frame by frame, the boot configurator against a scripted server, and the PDO
 * units (150 N m rated, 2^19 increments, gear 101: a round trip within one quantum). */
#include <math.h>
#include <string.h>

#include "arm/co_boot.h"
#include "arm/co_pdo.h"
#include "arm/co_sdo.h"
#include "check.h"

static arm_can_frame_t answer(uint8_t node, const uint8_t d[8])
{
    arm_can_frame_t f = {0};
    f.id = ARM_CO_COB_SDO_TX + node;
    f.len = 8u;
    memcpy(f.data, d, 8u);
    return f;
}

static uint32_t u32_at(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static void test_segmented_download(void)
{
    arm_co_sdo_t c;
    arm_co_sdo_init(&c, 5u, 1000u, 3u);
    uint8_t payload[20];
    for (unsigned i = 0; i < sizeof(payload); ++i) {
        payload[i] = (uint8_t)(0xA0u + i);
    }
    CHECK(arm_co_sdo_download(&c, 0x2000u, 3u, payload, sizeof(payload), 0u) == 0);
    CHECK(arm_co_sdo_download(&c, 0x2000u, 3u, payload, 4u, 0u) == -1); /* one at a time */
    arm_can_frame_t tx;
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1);
    CHECK(tx.id == 0x605u && tx.len == 8u && tx.data[0] == 0x21u && tx.data[1] == 0x00u && tx.data[2] == 0x20u &&
          tx.data[3] == 3u && u32_at(&tx.data[4]) == 20u);
    const uint8_t init_ok[8] = {0x60, 0x00, 0x20, 3, 0, 0, 0, 0};
    arm_can_frame_t rx = answer(5u, init_ok);
    CHECK(arm_co_sdo_rx(&c, &rx, 10u) == 1);
    /* 20 bytes = 7 + 7 + 6: toggles 0, 1, 0; the last has n = 1 unused byte and c = 1 */
    const uint8_t want_b0[3] = {0x00u, 0x10u, 0x03u};
    for (unsigned s = 0; s < 3u; ++s) {
        CHECK(arm_co_sdo_take_tx(&c, &tx) == 1);
        CHECK_MSG(tx.data[0] == want_b0[s], "segment %u: byte 0 0x%02X", s, tx.data[0]);
        CHECK(tx.data[1] == payload[7u * s]);
        const uint8_t seg_ok[8] = {(uint8_t)(0x20u | ((s & 1u) << 4)), 0, 0, 0, 0, 0, 0, 0};
        rx = answer(5u, seg_ok);
        CHECK(c.status == ARM_CO_SDO_BUSY);
        (void)arm_co_sdo_rx(&c, &rx, 20u + s);
    }
    CHECK(c.status == ARM_CO_SDO_DONE && c.tries == 1u);
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 0);
}

static void test_segmented_upload_and_toggle_error(void)
{
    arm_co_sdo_t c;
    arm_co_sdo_init(&c, 2u, 1000u, 3u);
    CHECK(arm_co_sdo_upload(&c, 0x1008u, 0u, 0u) == 0);
    arm_can_frame_t tx;
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.id == 0x602u && tx.data[0] == 0x40u);
    const uint8_t init[8] = {0x41, 0x08, 0x10, 0x00, 11, 0, 0, 0}; /* segmented, size 11 */
    arm_can_frame_t rx = answer(2u, init);
    (void)arm_co_sdo_rx(&c, &rx, 1u);
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x60u);
    const uint8_t seg0[8] = {0x00, 'C', 'i', 'A', ' ', '4', '0', '2'};
    rx = answer(2u, seg0);
    (void)arm_co_sdo_rx(&c, &rx, 2u);
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x70u);
    const uint8_t seg1[8] = {0x10u | (3u << 1) | 1u, ' ', 's', 'v', 'o', 0, 0, 0}; /* 4 bytes, last */
    rx = answer(2u, seg1);
    (void)arm_co_sdo_rx(&c, &rx, 3u);
    CHECK(c.status == ARM_CO_SDO_DONE && c.len == 11u && memcmp(c.data, "CiA 402 svo", 11u) == 0);

    /* the same upload, the server's second segment with the wrong toggle: the client aborts */
    CHECK(arm_co_sdo_upload(&c, 0x1008u, 0u, 10u) == 0);
    (void)arm_co_sdo_take_tx(&c, &tx);
    rx = answer(2u, init);
    (void)arm_co_sdo_rx(&c, &rx, 11u);
    (void)arm_co_sdo_take_tx(&c, &tx);
    rx = answer(2u, seg0);
    (void)arm_co_sdo_rx(&c, &rx, 12u);
    (void)arm_co_sdo_take_tx(&c, &tx);
    rx = answer(2u, seg0); /* toggle 0 again */
    (void)arm_co_sdo_rx(&c, &rx, 13u);
    CHECK(c.status == ARM_CO_SDO_ABORTED && c.abort_code == ARM_CO_ABORT_TOGGLE && !c.abort_by_server);
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x80u && u32_at(&tx.data[4]) == ARM_CO_ABORT_TOGGLE);

    /* a segmented upload larger than the buffer is refused at its initiate */
    CHECK(arm_co_sdo_upload(&c, 0x1008u, 0u, 20u) == 0);
    (void)arm_co_sdo_take_tx(&c, &tx);
    const uint8_t big[8] = {0x41, 0x08, 0x10, 0x00, (uint8_t)(ARM_CO_SDO_BUF + 1u), 0, 0, 0};
    rx = answer(2u, big);
    (void)arm_co_sdo_rx(&c, &rx, 21u);
    CHECK(c.status == ARM_CO_SDO_ABORTED && c.abort_code == ARM_CO_ABORT_NO_MEMORY);
}

static void test_abort_expedited_and_retries(void)
{
    arm_co_sdo_t c;
    arm_co_sdo_init(&c, 3u, 1000u, 3u);
    const uint8_t mode = 10u;
    CHECK(arm_co_sdo_download(&c, 0x6060u, 0u, &mode, 1u, 0u) == 0);
    arm_can_frame_t tx;
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x2Fu && tx.data[4] == 10u); /* e, s, n = 3 */
    const uint8_t abort[8] = {0x80, 0x60, 0x60, 0x00, 0x30, 0x00, 0x09, 0x06};
    arm_can_frame_t rx = answer(3u, abort);
    CHECK(arm_co_sdo_rx(&c, &rx, 5u) == 1);
    CHECK(c.status == ARM_CO_SDO_ABORTED && c.abort_code == ARM_CO_ABORT_RANGE && c.abort_by_server);
    CHECK(strcmp(arm_co_abort_text(c.abort_code), "value range of parameter exceeded") == 0);
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 0); /* nothing answers a server's abort */

    /* another node's answer is not ours */
    arm_co_sdo_init(&c, 3u, 1000u, 3u);
    CHECK(arm_co_sdo_upload(&c, 0x1000u, 0u, 0u) == 0);
    (void)arm_co_sdo_take_tx(&c, &tx);
    const uint8_t dev[8] = {0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00};
    rx = answer(4u, dev);
    CHECK(arm_co_sdo_rx(&c, &rx, 1u) == 0 && c.status == ARM_CO_SDO_BUSY);
    rx = answer(3u, dev);
    CHECK(arm_co_sdo_rx(&c, &rx, 2u) == 1 && c.status == ARM_CO_SDO_DONE);
    CHECK(arm_co_sdo_u32(&c) == ARM_CO_DEVICE_TYPE && c.len == 4u);

    /* no answer: the request goes out max_tries times, then abort 0x05040000 */
    CHECK(arm_co_sdo_upload(&c, 0x1018u, 1u, 100u) == 0);
    unsigned sent = 0u;
    for (uint64_t t = 100u; t < 100u + 10u * 1000u; t += 100u) {
        arm_co_sdo_tick(&c, t);
        while (arm_co_sdo_take_tx(&c, &tx)) {
            sent += tx.data[0] == 0x40u ? 1u : 0u;
            if (tx.data[0] == 0x80u) {
                CHECK(u32_at(&tx.data[4]) == ARM_CO_ABORT_TIMEOUT);
            }
        }
    }
    CHECK(sent == 3u && c.tries == 3u);
    CHECK(c.status == ARM_CO_SDO_TIMEOUT && c.abort_code == ARM_CO_ABORT_TIMEOUT);
}

/* An answer that comes after its try timed out: the retry's twin answer, which the server sends
 * too, must not fail the transfers that follow (seen with six python-canopen drives on a loaded
 * machine: "master aborted the response with 0x05040001"). */
static void test_a_late_answer_does_not_fail_the_next_transfer(void)
{
    arm_co_sdo_t c;
    arm_can_frame_t tx, rx;
    arm_co_sdo_init(&c, 3u, 1000u, 3u);
    CHECK(arm_co_sdo_upload(&c, 0x1018u, 3u, 0u) == 0);
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x40u);
    arm_co_sdo_tick(&c, 1000u); /* timed out: the retry */
    CHECK(arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x40u && c.tries == 2u);
    const uint8_t rev[8] = {0x43, 0x18, 0x10, 0x03, 0x07, 0x00, 0x00, 0x00};
    rx = answer(3u, rev); /* the first request's late answer completes the transfer */
    CHECK(arm_co_sdo_rx(&c, &rx, 1200u) == 1 && c.status == ARM_CO_SDO_DONE && arm_co_sdo_u32(&c) == 7u);
    CHECK(arm_co_sdo_upload(&c, 0x1018u, 4u, 1300u) == 0);
    (void)arm_co_sdo_take_tx(&c, &tx);
    CHECK(arm_co_sdo_rx(&c, &rx, 1400u) == 1); /* the retry's twin, for 0x1018:03 */
    CHECK(c.status == ARM_CO_SDO_BUSY && c.stale == 1u && arm_co_sdo_take_tx(&c, &tx) == 0);
    const uint8_t dl[8] = {0x60, 0x60, 0x60, 0x00, 0, 0, 0, 0}; /* a download's late answer, too */
    rx = answer(3u, dl);
    CHECK(arm_co_sdo_rx(&c, &rx, 1450u) == 1 && c.status == ARM_CO_SDO_BUSY && c.stale == 2u);
    const uint8_t serial[8] = {0x43, 0x18, 0x10, 0x04, 0x03, 0x00, 0x00, 0x00};
    rx = answer(3u, serial);
    CHECK(arm_co_sdo_rx(&c, &rx, 1500u) == 1 && c.status == ARM_CO_SDO_DONE && arm_co_sdo_u32(&c) == 3u);

    /* a segmented upload whose initiate was retried: the twin initiate answer mid-transfer */
    CHECK(arm_co_sdo_upload(&c, 0x1008u, 0u, 2000u) == 0);
    (void)arm_co_sdo_take_tx(&c, &tx);
    const uint8_t init[8] = {0x41, 0x08, 0x10, 0x00, 0x0B, 0x00, 0x00, 0x00};
    rx = answer(3u, init);
    CHECK(arm_co_sdo_rx(&c, &rx, 2100u) == 1 && arm_co_sdo_take_tx(&c, &tx) == 1 && tx.data[0] == 0x60u);
    CHECK(arm_co_sdo_rx(&c, &rx, 2150u) == 1 && c.status == ARM_CO_SDO_BUSY && c.stale == 3u);
    const uint8_t seg0[8] = {0x00, 'C', 'i', 'A', ' ', '4', '0', '2'};
    rx = answer(3u, seg0);
    CHECK(arm_co_sdo_rx(&c, &rx, 2200u) == 1 && c.status == ARM_CO_SDO_BUSY);
    const uint8_t seg1[8] = {0x19, ' ', 's', 'v', 0, 0, 0, 0};
    rx = answer(3u, seg1);
    CHECK(arm_co_sdo_rx(&c, &rx, 2250u) == 1 && c.status == ARM_CO_SDO_DONE && c.len == 10u);
}

/* A scripted CiA 402 server for every node: expedited SDO only, statusword follows controlword. */
typedef struct {
    uint16_t sw[128];
    uint32_t cob_rpdo1[128];
    int32_t mode[128];
    uint32_t device_type;
    unsigned writes;
    uint8_t identity_subs; /* 0x1018's highest sub-index (0: all four) */
} server_t;

static int serve(server_t *s, const arm_can_frame_t *req, arm_can_frame_t *resp)
{
    if (req->id < ARM_CO_COB_SDO_RX + 1u || req->id > ARM_CO_COB_SDO_RX + 127u) {
        return 0;
    }
    const uint8_t node = (uint8_t)(req->id - ARM_CO_COB_SDO_RX);
    const uint16_t index = (uint16_t)(req->data[1] | (req->data[2] << 8));
    const uint32_t v = u32_at(&req->data[4]);
    uint8_t d[8] = {0, req->data[1], req->data[2], req->data[3], 0, 0, 0, 0};
    if ((req->data[0] >> 5) == 1u) {
        s->writes++;
        d[0] = 0x60u;
        if (index == 0x6040u) {
            s->sw[node] = v == 0u ? 0x40u : v == 6u ? 0x21u : v == 7u ? 0x23u : v == 15u ? 0x27u : s->sw[node];
        } else if (index == 0x6060u) {
            s->mode[node] = (int8_t)v;
        } else if (index == 0x1400u && req->data[3] == 1u) {
            s->cob_rpdo1[node] = v;
        } else if (index == 0x1600u && !(s->cob_rpdo1[node] & ARM_CO_PDO_INVALID)) {
            d[0] = 0x80u;
            d[4] = 0x22; d[5] = 0x00; d[6] = 0x00; d[7] = 0x08; /* 0x08000022 */
        }
    } else if (index == 0x1018u && s->identity_subs != 0u && req->data[3] > s->identity_subs) {
        d[0] = 0x80u;
        d[4] = 0x11; d[5] = 0x00; d[6] = 0x09; d[7] = 0x06; /* 0x06090011: no such sub-index */
    } else {
        const uint32_t r = index == 0x1000u ? s->device_type : index == 0x6041u ? s->sw[node]
                         : index == 0x6061u ? (uint32_t)(uint8_t)s->mode[node] : 0x11u;
        d[0] = 0x43u;
        for (unsigned k = 0; k < 4u; ++k) {
            d[4u + k] = (uint8_t)(r >> (8u * k));
        }
    }
    *resp = answer(node, d);
    return 1;
}

static int run_boot(arm_co_boot_t *b, server_t *s, unsigned max_steps)
{
    int rc = 1;
    for (unsigned k = 0; k < max_steps && rc == 1; ++k) {
        const uint64_t now = (uint64_t)k * 1000u;
        rc = arm_co_boot_step(b, now);
        arm_can_frame_t tx, rx;
        while (arm_co_boot_take_tx(b, &tx)) {
            if (serve(s, &tx, &rx)) {
                arm_co_boot_rx(b, &rx, now + 100u);
            }
        }
    }
    return rc;
}

static void test_boot_sequence(void)
{
    static arm_co_boot_config_t cfg;
    static arm_co_boot_t b;
    static server_t s;
    arm_co_boot_default_config(&cfg);
    cfg.n_nodes = 2u;
    cfg.node[0] = (arm_co_node_config_t){.node_id = 1u};
    cfg.node[1] = (arm_co_node_config_t){.node_id = 2u, .overrides = ARM_CO_OVERRIDE_RATED | ARM_CO_OVERRIDE_GEAR,
                                         .rated_torque_mnm = 28000u, .gear_motor_revs = 160u, .gear_shaft_revs = 1u};
    memset(&s, 0, sizeof(s));
    s.device_type = ARM_CO_DEVICE_TYPE;
    s.sw[1] = 0x40u; /* switch on disabled: a fresh drive */
    s.sw[2] = 0x27u; /* left operation enabled by an earlier master: gets controlword 0x00 first */
    CHECK(arm_co_boot_init(&b, &cfg, 0u) == 0);
    CHECK(run_boot(&b, &s, 1000u) == 0);
    CHECK(b.node[0].state == ARM_CO_NODE_ENABLED && b.node[1].state == ARM_CO_NODE_ENABLED);
    /* per node: 3 PDOs x (5 + 2 entries) + 1006, 1017, 1016 + 6060 + three controlwords = 28 */
    CHECK_MSG(b.n_log == 28u + 32u, "%u writes", b.n_log); /* node 2: + 0x6076, 0x6091.1-2, the 0x00 */
    CHECK(s.writes == b.n_log);
    const arm_co_write_t *w = b.log;
    unsigned rated = 0u, disable = 0u;
    for (unsigned i = 0; i < b.n_log; ++i) {
        rated += (w[i].index == 0x6076u) ? 1u : 0u;
        if (w[i].index == 0x6040u && w[i].value == 0u) {
            ++disable;
            unsigned j = i + 1u;
            while (j < b.n_log && w[j].node != w[i].node) {
                ++j;
            }
            CHECK(w[i].node == 2u && j < b.n_log && w[j].index == 0x1400u); /* before the configuration */
        }
        if (w[i].index == 0x6076u) {
            CHECK(w[i].node == 2u && w[i].value == 28000u);
        }
    }
    CHECK(rated == 1u && disable == 1u);
    CHECK(s.mode[1] == 10 && s.mode[2] == 10 && s.sw[1] == 0x27u && s.sw[2] == 0x27u);

    /* a wrong device type is named: node, 0x1000, the value read */
    memset(&s, 0, sizeof(s));
    s.device_type = 0x00020191u;
    CHECK(arm_co_boot_init(&b, &cfg, 0u) == 0);
    CHECK(run_boot(&b, &s, 1000u) == -1);
    CHECK(b.fault.code == ARM_CO_FAULT_WRONG_VALUE && b.fault.node == 1u && b.fault.index == 0x1000u &&
          b.fault.value == 0x00020191u && b.fault.expected == ARM_CO_DEVICE_TYPE);

    /* CiA 301: 0x1018 sub 1 is mandatory, 2-4 are optional: a drive with sub 1 alone boots, its
     * others recorded as 0; unless the configuration checks the product code */
    memset(&s, 0, sizeof(s));
    s.device_type = ARM_CO_DEVICE_TYPE;
    s.identity_subs = 1u;
    s.sw[1] = s.sw[2] = 0x40u;
    CHECK(arm_co_boot_init(&b, &cfg, 0u) == 0);
    CHECK(run_boot(&b, &s, 1000u) == 0);
    CHECK(b.node[0].identity[0] == 0x11u && b.node[0].identity[1] == 0u && b.node[0].identity[3] == 0u);
    s.sw[1] = s.sw[2] = 0x40u;
    cfg.node[0].product_code = 0x11u;
    CHECK(arm_co_boot_init(&b, &cfg, 0u) == 0);
    CHECK(run_boot(&b, &s, 1000u) == -1);
    CHECK(b.fault.code == ARM_CO_FAULT_SDO_ABORT && b.fault.node == 1u && b.fault.index == 0x1018u &&
          b.fault.sub == 2u && b.fault.abort_code == 0x06090011u);
    cfg.node[0].product_code = 0u;

    /* a node id twice is a bad configuration, before anything is sent */
    cfg.node[1].node_id = 1u;
    CHECK(arm_co_boot_init(&b, &cfg, 0u) == -1 && b.fault.code == ARM_CO_FAULT_BAD_CONFIG && b.fault.node == 1u);
}

static void test_units(void)
{
    arm_co_units_t u;
    CHECK(arm_co_units_init(&u, 150000u, 1u << 19, 101u, 1u, 32767) == 0);
    CHECK(arm_co_units_init(&u, 0u, 1u << 19, 101u, 1u, 32767) == -1);
    CHECK(arm_co_units_init(&u, 150000u, 1u << 19, 101u, 1u, 32767) == 0);
    const float quantum_nm = 0.15f;
    const double quantum_rad = 2.0 * 3.14159265358979323846 / (524288.0 * 101.0);
    double worst_tau = 0.0, worst_q = 0.0;
    for (int k = -2000; k <= 2000; ++k) {
        const float tau = (float)k * 0.0731f;
        const float back = arm_co_permille_to_torque(&u, arm_co_torque_to_permille(&u, tau));
        worst_tau = fmax(worst_tau, fabs((double)back - (double)tau));
        const float q = (float)k * 0.00157f;
        const float qb = arm_co_increments_to_rad(&u, arm_co_rad_to_increments(&u, q));
        worst_q = fmax(worst_q, fabs((double)qb - (double)q));
    }
    CHECK_MSG(worst_tau <= 0.5 * quantum_nm + 1e-6, "torque round trip off by %g N m", worst_tau);
    /* float q itself carries 2^-24 relative: the round trip is within one increment plus that */
    CHECK_MSG(worst_q <= quantum_rad + 4e-7, "position round trip off by %g rad", worst_q);
    CHECK(arm_co_torque_to_permille(&u, 150.0f) == 1000);
    CHECK(arm_co_torque_to_permille(&u, 0.15f) == 1);
    CHECK(arm_co_torque_to_permille(&u, 1e9f) == 32767 && arm_co_torque_to_permille(&u, -1e9f) == -32767);
    CHECK(arm_co_torque_to_permille(&u, NAN) == 0 && arm_co_torque_to_permille(&u, INFINITY) == 0);
    CHECK(arm_co_increments_to_rad(&u, 524288 * 101) > 6.2831f && arm_co_increments_to_rad(&u, 524288 * 101) < 6.2832f);
    CHECK(arm_co_units_init(&u, 1000000u, 1u << 19, 101u, 1u, 1000) == 0); /* 1000 N m: 1 N m per-mille */
    CHECK(arm_co_torque_to_permille(&u, 2.5f) == 3 && arm_co_torque_to_permille(&u, -2.5f) == -3); /* halves away */
    CHECK(arm_co_torque_to_permille(&u, 5000.0f) == 1000); /* max_permille */
}

static void test_pdo_codec(void)
{
    arm_can_frame_t f;
    arm_co_pack_rpdo1(3u, 0x000Fu, -1000, &f);
    CHECK(f.id == 0x203u && f.len == 4u && f.data[0] == 0x0Fu && f.data[1] == 0u && f.data[2] == 0x18u &&
          f.data[3] == 0xFCu);
    arm_can_frame_t t1 = {.id = 0x183u, .len = 8u, .data = {0x00, 0x00, 0x38, 0x03, 0xFF, 0xFF, 0xFF, 0xFF}};
    int32_t pos = 0, vel = 0;
    CHECK(arm_co_unpack_tpdo1(3u, &t1, &pos, &vel) == 0 && pos == 0x03380000 && vel == -1);
    CHECK(arm_co_unpack_tpdo1(4u, &t1, &pos, &vel) == -1);
    t1.len = 7u;
    CHECK(arm_co_unpack_tpdo1(3u, &t1, &pos, &vel) == -1);
    arm_can_frame_t t2 = {.id = 0x283u, .len = 4u, .data = {0x18, 0xFC, 0x27, 0x02}};
    int16_t tq = 0;
    uint16_t sw = 0;
    CHECK(arm_co_unpack_tpdo2(3u, &t2, &tq, &sw) == 0 && tq == -1000 && sw == 0x0227u);
    arm_co_units_t u;
    CHECK(arm_co_units_init(&u, 150000u, 1u << 19, 101u, 1u, 32767) == 0);
    float q, qd, tau;
    arm_co_state_si(&u, pos, vel, tq, &q, &qd, &tau);
    CHECK(fabsf(tau + 150.0f) < 1e-4f && q > 0.0f && qd < 0.0f);
}

int main(void)
{
    test_segmented_download();
    test_segmented_upload_and_toggle_error();
    test_abort_expedited_and_retries();
    test_a_late_answer_does_not_fail_the_next_transfer();
    test_boot_sequence();
    test_units();
    test_pdo_codec();
    TEST_MAIN_END();
}
