/*
 * Unit tests for the python-can udp_multicast codec.
 *
 * Inputs are always decoded from the tail of a static buffer (decode_tail) so
 * that under ASan any read past the datagram runs into the global's redzone.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "arm/pycan_wire.h"
#include "check.h"
#include "pycan_golden.h"

/* Result-code check that names both codes, so a failure says what the decoder thought. */
#define CHECK_RC(expr, want)                                                             \
    do {                                                                                 \
        const int rc_got_ = (expr);                                                      \
        const int rc_want_ = (want);                                                     \
        CHECK_MSG(rc_got_ == rc_want_, "got %d (%s), want %d (%s)", rc_got_,             \
                  arm_pycan_errname(rc_got_), rc_want_, arm_pycan_errname(rc_want_));    \
    } while (0)

/* ---- helpers ---------------------------------------------------------- */

#define TAIL_CAP 1024u
static uint8_t g_tail[TAIL_CAP];

static int decode_tail(const uint8_t *src, size_t n, arm_can_frame_t *f, double *ts)
{
    if (n > TAIL_CAP) {
        return -1000;
    }
    uint8_t *dst = g_tail + (TAIL_CAP - n);
    if (n > 0u) {
        memmove(dst, src, n);
    }
    return arm_pycan_decode(dst, n, f, ts);
}

static arm_can_frame_t make_frame(uint32_t id, uint8_t len, uint8_t flags, uint8_t seed)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.len = len;
    f.flags = flags;
    for (unsigned i = 0; i < ARM_CAN_MAX_DATA; ++i) {
        f.data[i] = (uint8_t)(seed + 31u * i);
    }
    return f;
}

/* Equality as seen on the wire: RTR frames carry no data. */
static int frames_equal(const arm_can_frame_t *a, const arm_can_frame_t *b)
{
    if (a->id != b->id || a->len != b->len || a->flags != b->flags) {
        return 0;
    }
    if ((a->flags & ARM_CAN_FLAG_RTR) != 0u) {
        return 1;
    }
    return memcmp(a->data, b->data, a->len) == 0;
}

static int tail_zero(const arm_can_frame_t *f)
{
    const size_t used = (f->flags & ARM_CAN_FLAG_RTR) ? 0u : f->len;
    for (size_t i = used; i < ARM_CAN_MAX_DATA; ++i) {
        if (f->data[i] != 0u) {
            return 0;
        }
    }
    return 1;
}

/* ---- golden vectors --------------------------------------------------- */

typedef struct {
    const char *name;
    const uint8_t *bytes;
    size_t n;
    arm_can_frame_t frame;
    double ts;
} golden_t;

#define FD ARM_CAN_FLAG_FD
#define BRS ARM_CAN_FLAG_BRS
#define EXT ARM_CAN_FLAG_EXT
#define ESI ARM_CAN_FLAG_ESI
#define RTR ARM_CAN_FLAG_RTR
#define ERR ARM_CAN_FLAG_ERR

static size_t golden_table(golden_t *g)
{
    size_t k = 0;
    arm_can_frame_t f;

    memset(&f, 0, sizeof f);
    f.id = 0x123;
    f.len = 4;
    memcpy(f.data, (const uint8_t[]){0xDE, 0xAD, 0xBE, 0xEF}, 4);
    g[k++] = (golden_t){"classic_std", golden_classic_std, sizeof golden_classic_std, f, 1.5};

    memset(&f, 0, sizeof f);
    f.id = 0x1ABCDEF0;
    f.len = 64;
    f.flags = FD | BRS | EXT;
    for (unsigned i = 0; i < 64u; ++i) {
        f.data[i] = (uint8_t)i;
    }
    g[k++] = (golden_t){"fd_ext_brs_64", golden_fd_ext_brs_64, sizeof golden_fd_ext_brs_64, f,
                        1700000000.25};

    memset(&f, 0, sizeof f);
    f.id = 0x18FF00AA;
    f.len = 4;
    f.flags = EXT | RTR;
    g[k++] = (golden_t){"rtr_ext_dlc4", golden_rtr_ext_dlc4, sizeof golden_rtr_ext_dlc4, f, 0.0};

    memset(&f, 0, sizeof f);
    f.id = 0x7FF;
    g[k++] = (golden_t){"empty_std_7ff", golden_empty_std_7ff, sizeof golden_empty_std_7ff, f,
                        123.456};

    memset(&f, 0, sizeof f);
    f.id = 0x80;
    f.len = 12;
    f.flags = FD | ESI;
    for (unsigned i = 0; i < 12u; ++i) {
        f.data[i] = (uint8_t)(0xA0u + i);
    }
    g[k++] = (golden_t){"fd_std_esi_12", golden_fd_std_esi_12, sizeof golden_fd_std_esi_12, f, 0.1};

    memset(&f, 0, sizeof f);
    f.id = 0x1234;
    f.len = 8;
    f.flags = EXT | ERR;
    for (unsigned i = 0; i < 8u; ++i) {
        f.data[i] = (uint8_t)(1u + i);
    }
    g[k++] = (golden_t){"err_ext_1234", golden_err_ext_1234, sizeof golden_err_ext_1234, f, 42.0};
    return k;
}

static void test_golden(void)
{
    golden_t g[8];
    const size_t ng = golden_table(g);
    for (size_t i = 0; i < ng; ++i) {
        uint8_t buf[ARM_PYCAN_MAX_ENCODED];
        const size_t n = arm_pycan_encode(&g[i].frame, g[i].ts, buf, sizeof buf);
        const int same = n == g[i].n && memcmp(buf, g[i].bytes, n) == 0;
        if (!same) {
            printf("golden %s: encoded %zu bytes, python-can %zu bytes\n", g[i].name, n, g[i].n);
        }
        CHECK(same);

        arm_can_frame_t f;
        double ts = -1.0;
        CHECK_RC(decode_tail(g[i].bytes, g[i].n, &f, &ts), ARM_PYCAN_OK);
        CHECK(frames_equal(&f, &g[i].frame));
        CHECK(tail_zero(&f));
        CHECK(ts == g[i].ts);

        /* Encoder must need exactly n bytes: any smaller cap fails cleanly. */
        for (size_t cap = 0; cap < g[i].n; ++cap) {
            if (arm_pycan_encode(&g[i].frame, g[i].ts, buf, cap) != 0u) {
                CHECK(!"encode succeeded with too small cap");
                break;
            }
        }
        CHECK(arm_pycan_encode(&g[i].frame, g[i].ts, buf, g[i].n) == g[i].n);
    }
}

/* Every proper prefix of a valid datagram is a truncation, never a crash. */
static void test_truncations(void)
{
    golden_t g[8];
    const size_t ng = golden_table(g);
    for (size_t i = 0; i < ng; ++i) {
        unsigned bad = 0;
        for (size_t n = 0; n < g[i].n; ++n) {
            arm_can_frame_t f;
            double ts;
            const int rc = decode_tail(g[i].bytes, n, &f, &ts);
            if (rc != ARM_PYCAN_E_TRUNCATED) {
                printf("prefix %s[0..%zu) -> %s\n", g[i].name, n, arm_pycan_errname(rc));
                bad++;
            }
        }
        CHECK(bad == 0u);
    }
}

/* ---- round trips ------------------------------------------------------ */

static void round_trip(const arm_can_frame_t *in, double ts_in)
{
    uint8_t buf[ARM_PYCAN_MAX_ENCODED];
    const size_t n = arm_pycan_encode(in, ts_in, buf, sizeof buf);
    CHECK(n > 0u && n <= ARM_PYCAN_MAX_ENCODED);
    arm_can_frame_t out;
    memset(&out, 0xA5, sizeof out);
    double ts = -1.0;
    CHECK_RC(decode_tail(buf, n, &out, &ts), ARM_PYCAN_OK);
    CHECK(frames_equal(in, &out));
    CHECK(tail_zero(&out));
    CHECK(ts == ts_in);
}

static void test_round_trips(void)
{
    static const uint8_t fd_lens[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
    size_t max_n = 0;
    for (uint8_t len = 0; len <= 8u; ++len) {
        arm_can_frame_t f = make_frame(0x100u + len, len, 0, len);
        round_trip(&f, 1.0 + len);
        f.flags = EXT;
        f.id = 0x1FFFFFFFu - len;
        round_trip(&f, 0.0);
        f.flags = ERR;
        f.id = len;
        round_trip(&f, 3.25);
        f.flags = RTR;
        round_trip(&f, 1e9);
        f.flags = RTR | EXT;
        round_trip(&f, 1e-9);
    }
    for (size_t i = 0; i < sizeof fd_lens; ++i) {
        static const uint8_t fd_flag_sets[] = {FD, FD | BRS, FD | ESI, FD | BRS | ESI | EXT,
                                               FD | ERR};
        for (size_t j = 0; j < sizeof fd_flag_sets; ++j) {
            arm_can_frame_t f = make_frame((fd_flag_sets[j] & EXT) ? 0x1ABCDEFu : 0x7FFu,
                                           fd_lens[i], fd_flag_sets[j], (uint8_t)i);
            round_trip(&f, 1700000000.123456);
            uint8_t buf[ARM_PYCAN_MAX_ENCODED + 16];
            const size_t n = arm_pycan_encode(&f, 1.0, buf, sizeof buf);
            max_n = n > max_n ? n : max_n;
        }
    }
    /* Every integer width of the id encoder. */
    static const uint32_t ids[] = {0, 0x7F, 0x80, 0xFF, 0x100, 0xFFFF, 0x10000, 0x1FFFFFFF};
    for (size_t i = 0; i < sizeof ids / sizeof ids[0]; ++i) {
        arm_can_frame_t f = make_frame(ids[i], 3, EXT, 7);
        round_trip(&f, 5.0);
    }
    /* RTR: data content is irrelevant and must come back zeroed. */
    arm_can_frame_t rtr = make_frame(0x55, 8, RTR, 0xEE);
    round_trip(&rtr, 2.0);
    CHECK(max_n == ARM_PYCAN_MAX_ENCODED);
}

static void test_encode_rejects(void)
{
    uint8_t buf[ARM_PYCAN_MAX_ENCODED];
    arm_can_frame_t f = make_frame(0x123, 9, 0, 0); /* classic > 8 */
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    CHECK_RC(arm_pycan_frame_valid(&f), ARM_PYCAN_E_BAD_LENGTH);
    f = make_frame(0x123, 13, FD, 0); /* not an FD length */
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x123, 65, FD, 0);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x800, 0, 0, 0);
    CHECK_RC(arm_pycan_frame_valid(&f), ARM_PYCAN_E_BAD_ID);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x20000000, 0, EXT, 0);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x1, 0, BRS, 0);
    CHECK_RC(arm_pycan_frame_valid(&f), ARM_PYCAN_E_BAD_FLAGS);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x1, 0, ESI, 0);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x1, 0, RTR | FD, 0);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x1, 0, RTR | ERR, 0);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x1, 0, 0x40, 0); /* undefined flag bit */
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) == 0u);
    f = make_frame(0x1, 1, 0, 0);
    CHECK(arm_pycan_encode(&f, -1.0, buf, sizeof buf) == 0u);
    CHECK(arm_pycan_encode(&f, (double)NAN, buf, sizeof buf) == 0u);
    CHECK(arm_pycan_encode(&f, (double)INFINITY, buf, sizeof buf) == 0u);
    CHECK(arm_pycan_encode(&f, 0.0, buf, sizeof buf) > 0u);
    CHECK(arm_pycan_encode(NULL, 0.0, buf, sizeof buf) == 0u);
    CHECK(arm_pycan_encode(&f, 0.0, NULL, sizeof buf) == 0u);
    CHECK_RC(arm_pycan_frame_valid(NULL), ARM_PYCAN_E_ARG);
}

/* ---- hand-built maps for malformed inputs ----------------------------- */

typedef struct {
    uint8_t key[40];
    size_t klen;
    uint8_t val[80];
    size_t vlen;
} entry_t;

typedef struct {
    entry_t e[20];
    size_t n;
} mapspec_t;

static void put_str_key(entry_t *e, const char *k)
{
    const size_t n = strlen(k);
    e->key[0] = (uint8_t)(0xA0u | n);
    memcpy(e->key + 1, k, n);
    e->klen = n + 1u;
}

static void add_entry(mapspec_t *m, const char *k, const uint8_t *v, size_t vlen)
{
    entry_t *e = &m->e[m->n++];
    put_str_key(e, k);
    memcpy(e->val, v, vlen);
    e->vlen = vlen;
}

static entry_t *find_entry(mapspec_t *m, const char *k)
{
    for (size_t i = 0; i < m->n; ++i) {
        if (m->e[i].klen == strlen(k) + 1u && memcmp(m->e[i].key + 1, k, strlen(k)) == 0) {
            return &m->e[i];
        }
    }
    return NULL;
}

static void set_val(mapspec_t *m, const char *k, const uint8_t *v, size_t vlen)
{
    entry_t *e = find_entry(m, k);
    CHECK_MSG(e != NULL, "test bug: no key %s", k);
    if (e == NULL) {
        return;
    }
    memcpy(e->val, v, vlen);
    e->vlen = vlen;
}

static void drop_key(mapspec_t *m, const char *k)
{
    entry_t *e = find_entry(m, k);
    if (e != NULL) {
        const size_t idx = (size_t)(e - m->e);
        memmove(&m->e[idx], &m->e[idx + 1], (m->n - idx - 1u) * sizeof m->e[0]);
        m->n--;
    }
}

#define BYTES(...) (const uint8_t[]){__VA_ARGS__}, sizeof((const uint8_t[]){__VA_ARGS__})
#define SET(m, k, ...) set_val((m), (k), BYTES(__VA_ARGS__))
#define ADD(m, k, ...) add_entry((m), (k), BYTES(__VA_ARGS__))

/* Valid classic frame: id 0x123, data 11 22, timestamp 1.0. */
static void base_spec(mapspec_t *m)
{
    memset(m, 0, sizeof *m);
    ADD(m, "timestamp", 0xCB, 0x3F, 0xF0, 0, 0, 0, 0, 0, 0);
    ADD(m, "arbitration_id", 0xCD, 0x01, 0x23);
    ADD(m, "is_extended_id", 0xC2);
    ADD(m, "is_remote_frame", 0xC2);
    ADD(m, "is_error_frame", 0xC2);
    ADD(m, "channel", 0xC0);
    ADD(m, "dlc", 0x02);
    ADD(m, "data", 0xC4, 0x02, 0x11, 0x22);
    ADD(m, "is_fd", 0xC2);
    ADD(m, "bitrate_switch", 0xC2);
    ADD(m, "error_state_indicator", 0xC2);
}

enum { HDR_FIX, HDR_16, HDR_32 };

static size_t build(const mapspec_t *m, int hdr, uint8_t *out, size_t cap)
{
    size_t p = 0;
    if (hdr == HDR_FIX && m->n <= 15u) {
        out[p++] = (uint8_t)(0x80u | m->n);
    } else if (hdr == HDR_32) {
        out[p++] = 0xDF;
        out[p++] = 0;
        out[p++] = 0;
        out[p++] = (uint8_t)(m->n >> 8);
        out[p++] = (uint8_t)m->n;
    } else {
        out[p++] = 0xDE;
        out[p++] = (uint8_t)(m->n >> 8);
        out[p++] = (uint8_t)m->n;
    }
    for (size_t i = 0; i < m->n; ++i) {
        if (p + m->e[i].klen + m->e[i].vlen > cap) {
            return 0;
        }
        memcpy(out + p, m->e[i].key, m->e[i].klen);
        p += m->e[i].klen;
        memcpy(out + p, m->e[i].val, m->e[i].vlen);
        p += m->e[i].vlen;
    }
    return p;
}

static int decode_spec(const mapspec_t *m, int hdr, arm_can_frame_t *f, double *ts)
{
    uint8_t buf[1024];
    const size_t n = build(m, hdr, buf, sizeof buf);
    return decode_tail(buf, n, f, ts);
}

static int dec(const mapspec_t *m)
{
    arm_can_frame_t f;
    double ts;
    return decode_spec(m, HDR_FIX, &f, &ts);
}

static void test_accepts_variants(void)
{
    mapspec_t m;
    arm_can_frame_t f;
    double ts = 0.0;

    base_spec(&m);
    CHECK_RC(decode_spec(&m, HDR_FIX, &f, &ts), ARM_PYCAN_OK);
    CHECK(f.id == 0x123 && f.len == 2 && f.flags == 0 && f.data[0] == 0x11 && f.data[1] == 0x22);
    CHECK(ts == 1.0);
    CHECK_RC(decode_spec(&m, HDR_16, &f, &ts), ARM_PYCAN_OK);
    CHECK_RC(decode_spec(&m, HDR_32, &f, &ts), ARM_PYCAN_OK);

    /* any key order */
    mapspec_t r;
    memset(&r, 0, sizeof r);
    for (size_t i = 0; i < m.n; ++i) {
        r.e[i] = m.e[m.n - 1u - i];
    }
    r.n = m.n;
    CHECK_RC(decode_spec(&r, HDR_FIX, &f, &ts), ARM_PYCAN_OK);
    CHECK(f.id == 0x123 && f.len == 2);

    /* every integer encoding for id and dlc */
    static const uint8_t id_encs[][9] = {
        {0xCC, 0x00}, {0xCE, 0, 0, 0x01, 0x23}, {0xCF, 0, 0, 0, 0, 0, 0, 0x01, 0x23},
        {0xD0, 0x7F}, {0xD1, 0x01, 0x23},       {0xD2, 0, 0, 0x01, 0x23},
        {0xD3, 0, 0, 0, 0, 0, 0, 0x01, 0x23},
    };
    static const size_t id_lens[] = {2, 5, 9, 2, 3, 5, 9};
    for (size_t i = 0; i < sizeof id_lens / sizeof id_lens[0]; ++i) {
        base_spec(&m);
        set_val(&m, "arbitration_id", id_encs[i], id_lens[i]);
        CHECK_RC(dec(&m), ARM_PYCAN_OK);
        base_spec(&m);
        SET(&m, "dlc", 0xD3, 0, 0, 0, 0, 0, 0, 0, 2);
        CHECK_RC(dec(&m), ARM_PYCAN_OK);
    }
    base_spec(&m);
    SET(&m, "dlc", 0xCC, 2);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);

    /* float32 and int timestamps */
    base_spec(&m);
    SET(&m, "timestamp", 0xCA, 0x3F, 0xC0, 0, 0);
    CHECK_RC(decode_spec(&m, HDR_FIX, &f, &ts), ARM_PYCAN_OK);
    CHECK(ts == 1.5);
    SET(&m, "timestamp", 0x07);
    CHECK_RC(decode_spec(&m, HDR_FIX, &f, &ts), ARM_PYCAN_OK);
    CHECK(ts == 7.0);
    SET(&m, "timestamp", 0xCB, 0x80, 0, 0, 0, 0, 0, 0, 0); /* -0.0 passes python-can too */
    CHECK_RC(dec(&m), ARM_PYCAN_OK);

    /* channel: str, str8, int, or absent */
    base_spec(&m);
    SET(&m, "channel", 0xA5, 'v', 'c', 'a', 'n', '0');
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
    SET(&m, "channel", 0xD9, 0x02, 'c', '0');
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
    SET(&m, "channel", 0x01);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
    drop_key(&m, "channel");
    CHECK_RC(dec(&m), ARM_PYCAN_OK);

    /* data as bin16 / bin32 */
    base_spec(&m);
    SET(&m, "data", 0xC5, 0x00, 0x02, 0x11, 0x22);
    CHECK_RC(decode_spec(&m, HDR_FIX, &f, &ts), ARM_PYCAN_OK);
    CHECK(f.len == 2 && f.data[1] == 0x22);
    SET(&m, "data", 0xC6, 0, 0, 0x00, 0x02, 0x11, 0x22);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);

    /* unknown keys with simple values are skipped (fixmap up to 15, then map16) */
    base_spec(&m);
    ADD(&m, "is_rx", 0xC3);
    ADD(&m, "x_nil", 0xC0);
    ADD(&m, "x_neg", 0xD3, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFE);
    ADD(&m, "x_f32", 0xCA, 0, 0, 0, 0);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
    ADD(&m, "x_str", 0xDA, 0x00, 0x03, 'a', 'b', 'c');
    ADD(&m, "x_bin", 0xC4, 0x01, 0x00);
    ADD(&m, "x_u64", 0xCF, 1, 2, 3, 4, 5, 6, 7, 8);
    ADD(&m, "x_negfix", 0xE0);
    CHECK_RC(decode_spec(&m, HDR_16, &f, &ts), ARM_PYCAN_OK);
    CHECK(f.id == 0x123 && f.len == 2);

    /* a key that is a prefix / extension of a known key is just unknown */
    base_spec(&m);
    ADD(&m, "dl", 0x05);
    ADD(&m, "dlcx", 0x05);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
}

static void test_rejects_malformed(void)
{
    mapspec_t m;
    arm_can_frame_t f;
    double ts;

    /* not a map */
    CHECK_RC(decode_tail(BYTES(0x9B), &f, &ts), ARM_PYCAN_E_NOT_MAP);
    CHECK_RC(decode_tail(BYTES(0x01), &f, &ts), ARM_PYCAN_E_NOT_MAP);
    CHECK_RC(decode_tail(BYTES(0xC0), &f, &ts), ARM_PYCAN_E_NOT_MAP);
    CHECK_RC(decode_tail(BYTES(0xC4, 0x00), &f, &ts), ARM_PYCAN_E_NOT_MAP);
    CHECK_RC(decode_tail(BYTES(0x00), &f, &ts), ARM_PYCAN_E_NOT_MAP);
    CHECK_RC(decode_tail(NULL, 0, &f, &ts), ARM_PYCAN_E_TRUNCATED);

    /* NULL arguments */
    CHECK_RC(arm_pycan_decode(NULL, 4, &f, &ts), ARM_PYCAN_E_ARG);
    CHECK_RC(arm_pycan_decode(golden_classic_std, sizeof golden_classic_std, NULL, &ts),
             ARM_PYCAN_E_ARG);
    CHECK_RC(arm_pycan_decode(golden_classic_std, sizeof golden_classic_std, &f, NULL),
             ARM_PYCAN_OK);

    /* huge declared sizes must not be trusted */
    CHECK_RC(decode_tail(BYTES(0xDF, 0xFF, 0xFF, 0xFF, 0xFF), &f, &ts), ARM_PYCAN_E_TRUNCATED);
    CHECK_RC(decode_tail(BYTES(0x81, 0xDB, 0xFF, 0xFF, 0xFF, 0xFF, 'a'), &f, &ts),
             ARM_PYCAN_E_TRUNCATED);
    CHECK_RC(decode_tail(BYTES(0x81, 0xA1, 'x', 0xC6, 0xFF, 0xFF, 0xFF, 0xFF, 0), &f, &ts),
             ARM_PYCAN_E_TRUNCATED);
    CHECK_RC(decode_tail(BYTES(0x81, 0xA4, 'd', 'a', 't', 'a', 0xC6, 0xFF, 0xFF, 0xFF, 0xFF),
                         &f, &ts),
             ARM_PYCAN_E_TRUNCATED);

    /* key types */
    base_spec(&m);
    m.e[3].key[0] = 0x05; /* int key */
    m.e[3].klen = 1;
    CHECK_RC(dec(&m), ARM_PYCAN_E_KEY_TYPE);
    base_spec(&m);
    m.e[0].key[0] = 0xC4; /* bin key "timestamp" (msgpack-python would allow, Message(**) not) */
    memmove(m.e[0].key + 2, m.e[0].key + 1, 9);
    m.e[0].key[1] = 9;
    m.e[0].klen = 11;
    CHECK_RC(dec(&m), ARM_PYCAN_E_KEY_TYPE);

    /* duplicate known key; duplicate unknown keys are tolerated (skipped) */
    base_spec(&m);
    ADD(&m, "dlc", 0x02);
    CHECK_RC(dec(&m), ARM_PYCAN_E_DUPLICATE_KEY);
    base_spec(&m);
    ADD(&m, "is_fd", 0xC2);
    CHECK_RC(dec(&m), ARM_PYCAN_E_DUPLICATE_KEY);
    base_spec(&m);
    ADD(&m, "extra", 0xC2);
    ADD(&m, "extra", 0xC2);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);

    /* unknown key with a value we refuse to walk */
    static const uint8_t containers[][3] = {
        {0x90}, {0x80}, {0xDC, 0, 0}, {0xDE, 0, 0}, {0xD4, 1, 2}, {0xC7, 0, 1}, {0xC1},
    };
    static const size_t clens[] = {1, 1, 3, 3, 3, 3, 1};
    for (size_t i = 0; i < sizeof clens / sizeof clens[0]; ++i) {
        base_spec(&m);
        add_entry(&m, "extra", containers[i], clens[i]);
        CHECK_RC(dec(&m), ARM_PYCAN_E_UNSUPPORTED);
    }

    /* wrong types for known keys */
    base_spec(&m);
    SET(&m, "arbitration_id", 0xA1, 'x');
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "arbitration_id", 0xCB, 0x3F, 0xF0, 0, 0, 0, 0, 0, 0);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "dlc", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "data", 0xA2, 0x11, 0x22);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "data", 0x92, 0x11, 0x22);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "is_fd", 0x01);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "is_extended_id", 0xC0);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "timestamp", 0xA1, '1');
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "channel", 0xC4, 0x01, 0x00);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "channel", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);
    base_spec(&m);
    SET(&m, "dlc", 0xC1);
    CHECK_RC(dec(&m), ARM_PYCAN_E_WRONG_TYPE);

    /* each required key missing; channel is optional (tested above) */
    static const char *const required[] = {
        "timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame",
        "dlc",       "data",           "is_fd",          "bitrate_switch",  "error_state_indicator",
    };
    for (size_t i = 0; i < sizeof required / sizeof required[0]; ++i) {
        base_spec(&m);
        drop_key(&m, required[i]);
        CHECK_RC(dec(&m), ARM_PYCAN_E_MISSING_KEY);
    }
    CHECK_RC(decode_tail(BYTES(0x80), &f, &ts), ARM_PYCAN_E_MISSING_KEY);

    /* lengths */
    base_spec(&m);
    SET(&m, "dlc", 0x03); /* dlc != len(data) */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    SET(&m, "dlc", 0xFF); /* -1 */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    SET(&m, "dlc", 0xD3, 0x80, 0, 0, 0, 0, 0, 0, 2); /* hugely negative */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    SET(&m, "dlc", 0xCF, 0, 0, 0, 1, 0, 0, 0, 2); /* 2 + 2^32: must not wrap */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    base_spec(&m); /* classic with 9 bytes */
    SET(&m, "dlc", 0x09);
    SET(&m, "data", 0xC4, 9, 1, 2, 3, 4, 5, 6, 7, 8, 9);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    SET(&m, "is_fd", 0xC3); /* 9 is not an FD length either */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    {
        uint8_t big[2 + 65];
        big[0] = 0xC4;
        big[1] = 65;
        memset(big + 2, 0x5A, 65);
        base_spec(&m);
        SET(&m, "is_fd", 0xC3);
        SET(&m, "dlc", 65);
        set_val(&m, "data", big, sizeof big);
        CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
        big[1] = 64; /* 64 bytes: valid FD */
        set_val(&m, "data", big, sizeof big - 1u);
        SET(&m, "dlc", 64);
        CHECK_RC(dec(&m), ARM_PYCAN_OK);
        set_val(&m, "data", big, 2u + 13u); /* 13: within 64 but not an FD length */
        m.e[7].val[1] = 13;
        SET(&m, "dlc", 13);
        CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    }
    base_spec(&m); /* remote frame carrying data */
    SET(&m, "is_remote_frame", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);
    SET(&m, "data", 0xC4, 0x00);
    CHECK_RC(decode_spec(&m, HDR_FIX, &f, &ts), ARM_PYCAN_OK); /* dlc 2, no data: fine */
    CHECK(f.len == 2 && (f.flags & RTR) != 0u);
    SET(&m, "dlc", 0x09);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_LENGTH);

    /* ids */
    base_spec(&m);
    SET(&m, "arbitration_id", 0xCD, 0x08, 0x00);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_ID);
    SET(&m, "is_extended_id", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
    SET(&m, "arbitration_id", 0xCE, 0x20, 0, 0, 0);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_ID);
    SET(&m, "arbitration_id", 0xCE, 0x1F, 0xFF, 0xFF, 0xFF);
    CHECK_RC(dec(&m), ARM_PYCAN_OK);
    SET(&m, "arbitration_id", 0xCF, 0, 0, 0, 1, 0, 0, 0, 0x01); /* 2^32 + 1: must not wrap */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_ID);
    SET(&m, "arbitration_id", 0xD0, 0xFF);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_ID);
    SET(&m, "arbitration_id", 0xE0);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_ID);

    /* flags */
    base_spec(&m);
    SET(&m, "bitrate_switch", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_FLAGS);
    base_spec(&m);
    SET(&m, "error_state_indicator", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_FLAGS);
    base_spec(&m);
    SET(&m, "is_remote_frame", 0xC3);
    SET(&m, "data", 0xC4, 0x00);
    SET(&m, "is_fd", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_FLAGS);
    SET(&m, "is_fd", 0xC2);
    SET(&m, "is_error_frame", 0xC3);
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_FLAGS);

    /* timestamps */
    base_spec(&m);
    SET(&m, "timestamp", 0xCB, 0xBF, 0xF0, 0, 0, 0, 0, 0, 0); /* -1.0 */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_TIMESTAMP);
    SET(&m, "timestamp", 0xCB, 0x7F, 0xF8, 0, 0, 0, 0, 0, 0); /* NaN */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_TIMESTAMP);
    SET(&m, "timestamp", 0xCB, 0x7F, 0xF0, 0, 0, 0, 0, 0, 0); /* +inf */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_TIMESTAMP);
    SET(&m, "timestamp", 0xCA, 0x7F, 0x80, 0, 0); /* float32 +inf */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_TIMESTAMP);
    SET(&m, "timestamp", 0xFF); /* -1 */
    CHECK_RC(dec(&m), ARM_PYCAN_E_BAD_TIMESTAMP);

    /* trailing bytes */
    {
        uint8_t buf[sizeof golden_classic_std + 1];
        memcpy(buf, golden_classic_std, sizeof golden_classic_std);
        buf[sizeof golden_classic_std] = 0xC0;
        CHECK_RC(decode_tail(buf, sizeof buf, &f, &ts), ARM_PYCAN_E_TRAILING);
    }
}

static void test_error_names(void)
{
    for (int code = 1; code >= -20; --code) {
        CHECK(arm_pycan_strerror(code) != NULL);
        CHECK(arm_pycan_errname(code) != NULL);
    }
    CHECK(strcmp(arm_pycan_errname(ARM_PYCAN_E_TRUNCATED), "truncated") == 0);
    CHECK(strcmp(arm_pycan_errname(ARM_PYCAN_E_TRAILING), "trailing") == 0);
    CHECK(strcmp(arm_pycan_errname(12345), "unknown") == 0);
}

/* ---- mutation loop ---------------------------------------------------- */

static uint32_t g_rng = 0x2545F491u; /* fixed seed: failures must reproduce */

static uint32_t rnd(void)
{
    uint32_t x = g_rng;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    g_rng = x;
    return x;
}

static const uint8_t interesting[] = {0x00, 0x7F, 0x80, 0x8F, 0x90, 0xA0, 0xBF, 0xC0, 0xC1,
                                      0xC2, 0xC3, 0xC4, 0xC5, 0xC6, 0xCA, 0xCB, 0xCC, 0xCF,
                                      0xD0, 0xD3, 0xD9, 0xDB, 0xDE, 0xDF, 0xE0, 0xFF};

static size_t mutate(uint8_t *buf, size_t n, size_t cap)
{
    const unsigned rounds = 1u + rnd() % 4u;
    for (unsigned r = 0; r < rounds; ++r) {
        const uint32_t op = rnd() % 7u;
        const size_t at = n > 0u ? rnd() % n : 0u;
        switch (op) {
        case 0: /* flip one bit */
            if (n > 0u) {
                buf[at] ^= (uint8_t)(1u << (rnd() % 8u));
            }
            break;
        case 1: /* random byte */
            if (n > 0u) {
                buf[at] = (uint8_t)rnd();
            }
            break;
        case 2: /* msgpack-significant byte */
            if (n > 0u) {
                buf[at] = interesting[rnd() % sizeof interesting];
            }
            break;
        case 3: /* insert */
            if (n < cap) {
                memmove(buf + at + 1, buf + at, n - at);
                buf[at] = (uint8_t)rnd();
                n++;
            }
            break;
        case 4: /* delete */
            if (n > 0u) {
                memmove(buf + at, buf + at + 1, n - at - 1u);
                n--;
            }
            break;
        case 5: /* truncate */
            n = at;
            break;
        default: /* duplicate a chunk (creates duplicate keys, long maps) */
            if (n > 0u) {
                const size_t len = 1u + rnd() % 16u;
                const size_t src = rnd() % n;
                if (src + len <= n && n + len <= cap) {
                    memmove(buf + at + len, buf + at, n - at);
                    memmove(buf + at, buf + (src >= at ? src + len : src), len);
                    n += len;
                }
            }
            break;
        }
    }
    return n;
}

static void test_mutations(void)
{
    golden_t g[8];
    const size_t ng = golden_table(g);
    unsigned accepted = 0, invalid_accept = 0, reencode_fail = 0;
    const unsigned iterations = 100000u;
    for (unsigned it = 0; it < iterations; ++it) {
        uint8_t buf[512];
        size_t n;
        if (it % 16u == 15u) { /* pure noise, sometimes behind a map header */
            n = rnd() % 300u;
            for (size_t i = 0; i < n; ++i) {
                buf[i] = (uint8_t)rnd();
            }
            if (n > 0u && (it & 32u)) {
                buf[0] = (uint8_t)(0x80u | (rnd() & 0x0Fu));
            }
        } else {
            const golden_t *s = &g[rnd() % ng];
            memcpy(buf, s->bytes, s->n);
            n = mutate(buf, s->n, sizeof buf);
        }
        arm_can_frame_t f;
        double ts;
        if (decode_tail(buf, n, &f, &ts) == ARM_PYCAN_OK) {
            accepted++;
            /* anything we accept must be a frame we could legally send */
            if (arm_pycan_frame_valid(&f) != ARM_PYCAN_OK || !tail_zero(&f)) {
                invalid_accept++;
            }
            uint8_t out[ARM_PYCAN_MAX_ENCODED];
            if (arm_pycan_encode(&f, ts, out, sizeof out) == 0u) {
                reencode_fail++;
            }
        }
    }
    printf("mutations: %u iterations, %u accepted\n", iterations, accepted);
    CHECK(invalid_accept == 0u);
    CHECK(reencode_fail == 0u);
    CHECK(accepted > 0u); /* the mutator must also produce valid variants */
}

int main(void)
{
    test_golden();
    test_truncations();
    test_round_trips();
    test_encode_rejects();
    test_accepts_variants();
    test_rejects_malformed();
    test_error_names();
    test_mutations();
    TEST_MAIN_END();
}
