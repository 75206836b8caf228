/*
 * python-can udp_multicast codec (msgpack map per frame).
 *
 * The encoder mirrors msgpack-python's packer choices (smallest integer
 * encoding, float64 for floats, fixstr keys, bin8 data) so our bytes equal
 * pack_message()'s. The decoder is deliberately stricter than msgpack-python
 * in places where ambiguity would be dangerous on a control bus (duplicate
 * keys, missing keys) and never walks nested containers, so it needs neither
 * recursion nor a stack.
 */
#include "arm/pycan_wire.h"

#include <string.h>

_Static_assert(sizeof(double) == sizeof(uint64_t), "msgpack float64 needs a 64-bit double");
_Static_assert(sizeof(float) == sizeof(uint32_t), "msgpack float32 needs a 32-bit float");

#define STD_ID_MAX 0x7FFu
#define EXT_ID_MAX 0x1FFFFFFFu
#define CLASSIC_MAX_LEN 8u
#define KNOWN_FLAGS                                                                      \
    (ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS | ARM_CAN_FLAG_EXT | ARM_CAN_FLAG_ESI |          \
     ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_ERR)

/* Key order is python-can's pack_message dict order; the encoder relies on it. */
enum {
    K_TIMESTAMP,
    K_ARBITRATION_ID,
    K_IS_EXTENDED_ID,
    K_IS_REMOTE_FRAME,
    K_IS_ERROR_FRAME,
    K_CHANNEL,
    K_DLC,
    K_DATA,
    K_IS_FD,
    K_BITRATE_SWITCH,
    K_ERROR_STATE_INDICATOR,
    K_COUNT
};

static const char *const key_names[K_COUNT] = {
    "timestamp",      "arbitration_id", "is_extended_id", "is_remote_frame",
    "is_error_frame", "channel",        "dlc",            "data",
    "is_fd",          "bitrate_switch", "error_state_indicator",
};

/* channel is ignored on receive, so a sender may leave it out. */
#define REQUIRED_KEYS (((1u << K_COUNT) - 1u) & ~(1u << K_CHANNEL))

static int fd_len_valid(unsigned len)
{
    if (len <= CLASSIC_MAX_LEN) {
        return 1;
    }
    switch (len) {
    case 12: case 16: case 20: case 24: case 32: case 48: case 64:
        return 1;
    default:
        return 0;
    }
}

/* NaN and +-inf both fail x - x == 0; avoids <math.h> to stay freestanding-friendly. */
static int timestamp_valid(double t)
{
    return (t - t == 0.0) && !(t < 0.0);
}

int arm_pycan_frame_valid(const arm_can_frame_t *f)
{
    if (f == NULL) {
        return ARM_PYCAN_E_ARG;
    }
    const unsigned flags = f->flags;
    if ((flags & ~KNOWN_FLAGS) != 0u) {
        return ARM_PYCAN_E_BAD_FLAGS;
    }
    if (f->id > ((flags & ARM_CAN_FLAG_EXT) ? EXT_ID_MAX : STD_ID_MAX)) {
        return ARM_PYCAN_E_BAD_ID;
    }
    const int fd = (flags & ARM_CAN_FLAG_FD) != 0u;
    if (!fd && (flags & (ARM_CAN_FLAG_BRS | ARM_CAN_FLAG_ESI)) != 0u) {
        return ARM_PYCAN_E_BAD_FLAGS;
    }
    if ((flags & ARM_CAN_FLAG_RTR) != 0u && (fd || (flags & ARM_CAN_FLAG_ERR) != 0u)) {
        return ARM_PYCAN_E_BAD_FLAGS;
    }
    if (fd ? !fd_len_valid(f->len) : f->len > CLASSIC_MAX_LEN) {
        return ARM_PYCAN_E_BAD_LENGTH;
    }
    return ARM_PYCAN_OK;
}

/* ---- encoder ---------------------------------------------------------- */

typedef struct {
    uint8_t *buf;
    size_t cap;
    size_t pos;
    int overflow;
} writer_t;

static void w_bytes(writer_t *w, const void *src, size_t k)
{
    if (w->overflow || k > w->cap - w->pos) {
        w->overflow = 1;
        return;
    }
    memcpy(w->buf + w->pos, src, k);
    w->pos += k;
}

static void w_u8(writer_t *w, uint8_t b)
{
    w_bytes(w, &b, 1u);
}

static void w_be(writer_t *w, uint64_t v, unsigned nbytes)
{
    uint8_t tmp[8];
    for (unsigned i = 0; i < nbytes && i < 8u; ++i) {
        tmp[i] = (uint8_t)(v >> (8u * (nbytes - 1u - i)));
    }
    w_bytes(w, tmp, nbytes);
}

static void w_key(writer_t *w, unsigned k)
{
    const size_t len = strlen(key_names[k]); /* all < 32: fixstr */
    w_u8(w, (uint8_t)(0xA0u | len));
    w_bytes(w, key_names[k], len);
}

/* Same width choice as msgpack-python for non-negative ints. */
static void w_uint(writer_t *w, uint64_t v)
{
    if (v < 0x80u) {
        w_u8(w, (uint8_t)v);
    } else if (v <= 0xFFu) {
        w_u8(w, 0xCC);
        w_be(w, v, 1u);
    } else if (v <= 0xFFFFu) {
        w_u8(w, 0xCD);
        w_be(w, v, 2u);
    } else if (v <= 0xFFFFFFFFu) {
        w_u8(w, 0xCE);
        w_be(w, v, 4u);
    } else {
        w_u8(w, 0xCF);
        w_be(w, v, 8u);
    }
}

static void w_bool(writer_t *w, unsigned flags, unsigned bit)
{
    w_u8(w, (flags & bit) ? 0xC3 : 0xC2);
}

size_t arm_pycan_encode(const arm_can_frame_t *f, double timestamp, uint8_t *buf, size_t cap)
{
    if (f == NULL || buf == NULL || arm_pycan_frame_valid(f) != ARM_PYCAN_OK ||
        !timestamp_valid(timestamp)) {
        return 0;
    }
    const unsigned flags = f->flags;
    const int rtr = (flags & ARM_CAN_FLAG_RTR) != 0u;
    /* python-can Message drops data for remote frames; dlc keeps the request. */
    const size_t data_len = rtr ? 0u : f->len;
    uint64_t ts_bits;
    memcpy(&ts_bits, &timestamp, sizeof ts_bits);

    writer_t w = {buf, cap, 0u, 0};
    w_u8(&w, (uint8_t)(0x80u | K_COUNT));
    w_key(&w, K_TIMESTAMP);
    w_u8(&w, 0xCB);
    w_be(&w, ts_bits, 8u);
    w_key(&w, K_ARBITRATION_ID);
    w_uint(&w, f->id);
    w_key(&w, K_IS_EXTENDED_ID);
    w_bool(&w, flags, ARM_CAN_FLAG_EXT);
    w_key(&w, K_IS_REMOTE_FRAME);
    w_bool(&w, flags, ARM_CAN_FLAG_RTR);
    w_key(&w, K_IS_ERROR_FRAME);
    w_bool(&w, flags, ARM_CAN_FLAG_ERR);
    w_key(&w, K_CHANNEL);
    w_u8(&w, 0xC0);
    w_key(&w, K_DLC);
    w_uint(&w, f->len);
    w_key(&w, K_DATA);
    w_u8(&w, 0xC4);
    w_u8(&w, (uint8_t)data_len);
    w_bytes(&w, f->data, data_len);
    w_key(&w, K_IS_FD);
    w_bool(&w, flags, ARM_CAN_FLAG_FD);
    w_key(&w, K_BITRATE_SWITCH);
    w_bool(&w, flags, ARM_CAN_FLAG_BRS);
    w_key(&w, K_ERROR_STATE_INDICATOR);
    w_bool(&w, flags, ARM_CAN_FLAG_ESI);
    return w.overflow ? 0u : w.pos;
}

/* ---- decoder ---------------------------------------------------------- */

typedef struct {
    const uint8_t *p;
    size_t n;
    size_t pos;
} reader_t;

static size_t r_left(const reader_t *r)
{
    return r->n - r->pos;
}

/* Caller has checked r_left() >= nbytes. */
static uint64_t r_be(reader_t *r, unsigned nbytes)
{
    uint64_t v = 0;
    for (unsigned i = 0; i < nbytes && i < 8u; ++i) {
        v = (v << 8) | r->p[r->pos + i];
    }
    r->pos += nbytes;
    return v;
}

/* Reads a big-endian length/value of nbytes, or reports truncation. */
static int r_be_checked(reader_t *r, unsigned nbytes, uint64_t *out)
{
    if (r_left(r) < nbytes) {
        return ARM_PYCAN_E_TRUNCATED;
    }
    *out = r_be(r, nbytes);
    return ARM_PYCAN_OK;
}

/* Advances past a payload of len bytes (len may come from a 32-bit header). */
static int r_skip(reader_t *r, uint64_t len)
{
    if (len > (uint64_t)r_left(r)) {
        return ARM_PYCAN_E_TRUNCATED;
    }
    r->pos += (size_t)len;
    return ARM_PYCAN_OK;
}

/*
 * Classifies the object at the cursor by its msgpack type byte.
 * For str/bin it consumes the header and returns the payload length in *len;
 * for int/float it consumes the header byte and returns the payload width in
 * *len (0 for fix types); for nil/bool it consumes the byte.
 */
typedef enum {
    T_NIL, T_BOOL, T_UINT, T_NEGINT, T_SINT, T_FLOAT32, T_FLOAT64, T_STR, T_BIN, T_CONTAINER,
    T_INVALID
} mtype_t;

static int r_type(reader_t *r, mtype_t *type, uint64_t *len, uint8_t *tag)
{
    if (r_left(r) < 1u) {
        return ARM_PYCAN_E_TRUNCATED;
    }
    const uint8_t b = r->p[r->pos++];
    *tag = b;
    *len = 0;
    if (b <= 0x7Fu) {
        *type = T_UINT; /* positive fixint: value is the tag */
        return ARM_PYCAN_OK;
    }
    if (b >= 0xE0u) {
        *type = T_NEGINT; /* negative fixint */
        return ARM_PYCAN_OK;
    }
    if (b >= 0xA0u && b <= 0xBFu) {
        *type = T_STR;
        *len = b & 0x1Fu;
        return ARM_PYCAN_OK;
    }
    if (b <= 0x9Fu) {
        *type = T_CONTAINER; /* fixmap, fixarray */
        return ARM_PYCAN_OK;
    }
    switch (b) {
    case 0xC0: *type = T_NIL; return ARM_PYCAN_OK;
    case 0xC2: case 0xC3: *type = T_BOOL; return ARM_PYCAN_OK;
    case 0xC4: *type = T_BIN; return r_be_checked(r, 1u, len);
    case 0xC5: *type = T_BIN; return r_be_checked(r, 2u, len);
    case 0xC6: *type = T_BIN; return r_be_checked(r, 4u, len);
    case 0xCA: *type = T_FLOAT32; *len = 4; return ARM_PYCAN_OK;
    case 0xCB: *type = T_FLOAT64; *len = 8; return ARM_PYCAN_OK;
    case 0xCC: *type = T_UINT; *len = 1; return ARM_PYCAN_OK;
    case 0xCD: *type = T_UINT; *len = 2; return ARM_PYCAN_OK;
    case 0xCE: *type = T_UINT; *len = 4; return ARM_PYCAN_OK;
    case 0xCF: *type = T_UINT; *len = 8; return ARM_PYCAN_OK;
    case 0xD0: *type = T_SINT; *len = 1; return ARM_PYCAN_OK;
    case 0xD1: *type = T_SINT; *len = 2; return ARM_PYCAN_OK;
    case 0xD2: *type = T_SINT; *len = 4; return ARM_PYCAN_OK;
    case 0xD3: *type = T_SINT; *len = 8; return ARM_PYCAN_OK;
    case 0xD9: *type = T_STR; return r_be_checked(r, 1u, len);
    case 0xDA: *type = T_STR; return r_be_checked(r, 2u, len);
    case 0xDB: *type = T_STR; return r_be_checked(r, 4u, len);
    case 0xC7: case 0xC8: case 0xC9: /* ext */
    case 0xD4: case 0xD5: case 0xD6: case 0xD7: case 0xD8: /* fixext */
    case 0xDC: case 0xDD: case 0xDE: case 0xDF: /* array16/32, map16/32 */
        *type = T_CONTAINER;
        return ARM_PYCAN_OK;
    default: /* 0xC1 is reserved ("never used") */
        *type = T_INVALID;
        return ARM_PYCAN_OK;
    }
}

static int is_int(mtype_t t)
{
    return t == T_UINT || t == T_NEGINT || t == T_SINT;
}

/*
 * Reads the integer whose header r_type just consumed. Signed encodings of
 * non-negative values are accepted: other packers legitimately emit them.
 */
static int r_int_body(reader_t *r, mtype_t t, uint64_t width, uint8_t tag, int *neg,
                      uint64_t *mag)
{
    *neg = 0;
    if (t == T_NEGINT) {
        *neg = 1;
        *mag = 256u - tag;
        return ARM_PYCAN_OK;
    }
    if (width == 0u) {
        *mag = tag;
        return ARM_PYCAN_OK;
    }
    uint64_t raw;
    const int rc = r_be_checked(r, (unsigned)width, &raw);
    if (rc != ARM_PYCAN_OK) {
        return rc;
    }
    if (t == T_SINT) {
        const uint64_t sign = (uint64_t)1u << (8u * width - 1u);
        if ((raw & sign) != 0u) {
            *neg = 1;
            /* two's complement magnitude within `width` bytes */
            const uint64_t mask = (width == 8u) ? ~(uint64_t)0 : ((sign << 1) - 1u);
            *mag = ((~raw) & mask) + 1u;
            return ARM_PYCAN_OK;
        }
    }
    *mag = raw;
    return ARM_PYCAN_OK;
}

/* Skips a value of an unknown key; refuses anything that would need recursion. */
static int r_skip_simple(reader_t *r, mtype_t t, uint64_t len)
{
    switch (t) {
    case T_NIL:
    case T_BOOL:
    case T_NEGINT:
    case T_UINT:
    case T_SINT:
    case T_FLOAT32:
    case T_FLOAT64:
    case T_STR:
    case T_BIN:
        return r_skip(r, len);
    default:
        return ARM_PYCAN_E_UNSUPPORTED;
    }
}

static int match_key(const uint8_t *s, uint64_t len)
{
    for (int k = 0; k < K_COUNT; ++k) {
        const size_t kl = strlen(key_names[k]);
        if (len == kl && memcmp(s, key_names[k], kl) == 0) {
            return k;
        }
    }
    return -1;
}

typedef struct {
    unsigned seen;
    unsigned flags;
    uint64_t id;
    uint64_t dlc;
    size_t data_off;
    size_t data_len;
    double ts;
} fields_t;

static int read_timestamp(reader_t *r, mtype_t t, uint64_t width, uint8_t tag, double *ts)
{
    if (t == T_FLOAT64 || t == T_FLOAT32) {
        uint64_t raw;
        const int rc = r_be_checked(r, (unsigned)width, &raw);
        if (rc != ARM_PYCAN_OK) {
            return rc;
        }
        if (t == T_FLOAT64) {
            memcpy(ts, &raw, sizeof *ts);
        } else {
            const uint32_t raw32 = (uint32_t)raw;
            float f32;
            memcpy(&f32, &raw32, sizeof f32);
            *ts = (double)f32;
        }
    } else if (is_int(t)) {
        /* python-can keeps an int timestamp if a user passed one */
        int neg;
        uint64_t mag;
        const int rc = r_int_body(r, t, width, tag, &neg, &mag);
        if (rc != ARM_PYCAN_OK) {
            return rc;
        }
        if (neg) {
            return ARM_PYCAN_E_BAD_TIMESTAMP;
        }
        *ts = (double)mag;
    } else {
        return ARM_PYCAN_E_WRONG_TYPE;
    }
    return timestamp_valid(*ts) ? ARM_PYCAN_OK : ARM_PYCAN_E_BAD_TIMESTAMP;
}

static int read_uint_field(reader_t *r, mtype_t t, uint64_t width, uint8_t tag, int neg_err,
                           uint64_t *out)
{
    if (!is_int(t)) {
        return ARM_PYCAN_E_WRONG_TYPE;
    }
    int neg;
    const int rc = r_int_body(r, t, width, tag, &neg, out);
    if (rc != ARM_PYCAN_OK) {
        return rc;
    }
    return neg ? neg_err : ARM_PYCAN_OK;
}

static int read_value(reader_t *r, int key, fields_t *fl)
{
    static const uint8_t bool_flag[K_COUNT] = {
        [K_IS_EXTENDED_ID] = ARM_CAN_FLAG_EXT,   [K_IS_REMOTE_FRAME] = ARM_CAN_FLAG_RTR,
        [K_IS_ERROR_FRAME] = ARM_CAN_FLAG_ERR,   [K_IS_FD] = ARM_CAN_FLAG_FD,
        [K_BITRATE_SWITCH] = ARM_CAN_FLAG_BRS,   [K_ERROR_STATE_INDICATOR] = ARM_CAN_FLAG_ESI,
    };
    mtype_t t;
    uint64_t len;
    uint8_t tag;
    int rc = r_type(r, &t, &len, &tag);
    if (rc != ARM_PYCAN_OK) {
        return rc;
    }
    if (key < 0) {
        return r_skip_simple(r, t, len);
    }
    switch (key) {
    case K_TIMESTAMP:
        return read_timestamp(r, t, len, tag, &fl->ts);
    case K_ARBITRATION_ID:
        return read_uint_field(r, t, len, tag, ARM_PYCAN_E_BAD_ID, &fl->id);
    case K_DLC:
        return read_uint_field(r, t, len, tag, ARM_PYCAN_E_BAD_LENGTH, &fl->dlc);
    case K_CHANNEL:
        /* value irrelevant to us; python-can uses str, None or int */
        if (t == T_NIL || t == T_STR || is_int(t)) {
            return r_skip(r, len);
        }
        return ARM_PYCAN_E_WRONG_TYPE;
    case K_DATA:
        if (t != T_BIN) {
            return ARM_PYCAN_E_WRONG_TYPE;
        }
        fl->data_off = r->pos;
        rc = r_skip(r, len);
        if (rc != ARM_PYCAN_OK) {
            return rc;
        }
        if (len > ARM_CAN_MAX_DATA) {
            return ARM_PYCAN_E_BAD_LENGTH;
        }
        fl->data_len = (size_t)len;
        return ARM_PYCAN_OK;
    default:
        if (t != T_BOOL) {
            return ARM_PYCAN_E_WRONG_TYPE;
        }
        if (tag == 0xC3) {
            fl->flags |= bool_flag[key];
        }
        return ARM_PYCAN_OK;
    }
}

static int r_map_header(reader_t *r, uint64_t *count)
{
    if (r_left(r) < 1u) {
        return ARM_PYCAN_E_TRUNCATED;
    }
    const uint8_t b = r->p[r->pos++];
    if (b >= 0x80u && b <= 0x8Fu) {
        *count = b & 0x0Fu;
        return ARM_PYCAN_OK;
    }
    if (b == 0xDE) {
        return r_be_checked(r, 2u, count);
    }
    if (b == 0xDF) {
        return r_be_checked(r, 4u, count);
    }
    return ARM_PYCAN_E_NOT_MAP;
}

static int read_fields(reader_t *r, fields_t *fl)
{
    uint64_t count;
    int rc = r_map_header(r, &count);
    if (rc != ARM_PYCAN_OK) {
        return rc;
    }
    /* Bounded: every entry consumes at least two bytes or we return. */
    for (uint64_t i = 0; i < count; ++i) {
        mtype_t t;
        uint64_t klen;
        uint8_t tag;
        rc = r_type(r, &t, &klen, &tag);
        if (rc != ARM_PYCAN_OK) {
            return rc;
        }
        if (t != T_STR) {
            return ARM_PYCAN_E_KEY_TYPE;
        }
        const size_t key_off = r->pos;
        rc = r_skip(r, klen);
        if (rc != ARM_PYCAN_OK) {
            return rc;
        }
        const int key = match_key(r->p + key_off, klen);
        if (key >= 0) {
            if (fl->seen & (1u << key)) {
                return ARM_PYCAN_E_DUPLICATE_KEY;
            }
            fl->seen |= 1u << key;
        }
        rc = read_value(r, key, fl);
        if (rc != ARM_PYCAN_OK) {
            return rc;
        }
    }
    if (r->pos != r->n) {
        return ARM_PYCAN_E_TRAILING;
    }
    return (fl->seen & REQUIRED_KEYS) == REQUIRED_KEYS ? ARM_PYCAN_OK : ARM_PYCAN_E_MISSING_KEY;
}

int arm_pycan_decode(const uint8_t *buf, size_t n, arm_can_frame_t *f, double *timestamp)
{
    if (buf == NULL || f == NULL) {
        return ARM_PYCAN_E_ARG;
    }
    reader_t r = {buf, n, 0u};
    fields_t fl = {0u, 0u, 0u, 0u, 0u, 0u, 0.0};
    int rc = read_fields(&r, &fl);
    if (rc != ARM_PYCAN_OK) {
        return rc;
    }
    if (fl.id > EXT_ID_MAX) {
        return ARM_PYCAN_E_BAD_ID;
    }
    if (fl.dlc > ARM_CAN_MAX_DATA) {
        return ARM_PYCAN_E_BAD_LENGTH;
    }
    /* python-can's check: remote frames carry no data; others need dlc == len(data). */
    if ((fl.flags & ARM_CAN_FLAG_RTR) ? fl.data_len != 0u : fl.dlc != fl.data_len) {
        return ARM_PYCAN_E_BAD_LENGTH;
    }
    memset(f, 0, sizeof *f);
    f->id = (uint32_t)fl.id;
    f->len = (uint8_t)fl.dlc;
    f->flags = (uint8_t)fl.flags;
    rc = arm_pycan_frame_valid(f);
    if (rc != ARM_PYCAN_OK) {
        return rc;
    }
    memcpy(f->data, buf + fl.data_off, fl.data_len);
    if (timestamp != NULL) {
        *timestamp = fl.ts;
    }
    return ARM_PYCAN_OK;
}

/* ---- error names ------------------------------------------------------ */

typedef struct {
    int code;
    const char *name;
    const char *text;
} err_info_t;

static const err_info_t err_table[] = {
    {ARM_PYCAN_OK, "ok", "success"},
    {ARM_PYCAN_E_ARG, "arg", "NULL argument"},
    {ARM_PYCAN_E_TRUNCATED, "truncated", "datagram ends inside a msgpack object"},
    {ARM_PYCAN_E_NOT_MAP, "not_map", "top-level msgpack object is not a map"},
    {ARM_PYCAN_E_KEY_TYPE, "key_type", "map key is not a string"},
    {ARM_PYCAN_E_DUPLICATE_KEY, "duplicate_key", "known key appears more than once"},
    {ARM_PYCAN_E_UNSUPPORTED, "unsupported",
     "unknown key with container/ext value, or reserved byte"},
    {ARM_PYCAN_E_WRONG_TYPE, "wrong_type", "known key has the wrong msgpack type"},
    {ARM_PYCAN_E_MISSING_KEY, "missing_key", "required key missing"},
    {ARM_PYCAN_E_BAD_LENGTH, "bad_length", "dlc/data length invalid or inconsistent"},
    {ARM_PYCAN_E_BAD_ID, "bad_id", "arbitration id out of range"},
    {ARM_PYCAN_E_BAD_FLAGS, "bad_flags", "invalid flag combination"},
    {ARM_PYCAN_E_BAD_TIMESTAMP, "bad_timestamp", "timestamp negative, infinite or NaN"},
    {ARM_PYCAN_E_TRAILING, "trailing", "bytes after the msgpack map"},
};

static const err_info_t *err_lookup(int code)
{
    for (size_t i = 0; i < sizeof err_table / sizeof err_table[0]; ++i) {
        if (err_table[i].code == code) {
            return &err_table[i];
        }
    }
    return NULL;
}

const char *arm_pycan_strerror(int code)
{
    const err_info_t *e = err_lookup(code);
    return e != NULL ? e->text : "unknown error code";
}

const char *arm_pycan_errname(int code)
{
    const err_info_t *e = err_lookup(code);
    return e != NULL ? e->name : "unknown";
}
