#include "pil_link.h"

#include <string.h>

/* ---- little-endian writer and reader, bounded by the buffer ---------------------------------- */

typedef struct {
    uint8_t *p;
    size_t len, cap;
    int overflow;
} wr_t;

static void put(wr_t *w, const void *src, size_t n)
{
    if (w->len + n > w->cap) {
        w->overflow = 1;
        return;
    }
    memcpy(w->p + w->len, src, n); /* little-endian target and host: the bytes as they are */
    w->len += n;
}

static void u8(wr_t *w, uint32_t v) { const uint8_t b = (uint8_t)v; put(w, &b, 1); }
static void u16(wr_t *w, uint32_t v) { const uint16_t b = (uint16_t)v; put(w, &b, 2); }
static void u32(wr_t *w, uint32_t v) { put(w, &v, 4); }
static void u64(wr_t *w, uint64_t v) { put(w, &v, 8); }
static void f32s(wr_t *w, const float *v, unsigned n) { put(w, v, 4u * n); }
static void f64(wr_t *w, double v) { put(w, &v, 8); }

static void text(wr_t *w, const char *s, size_t cap)
{
    size_t n = 0;
    while (n < cap && s[n] != '\0') ++n;
    u16(w, (uint32_t)n);
    put(w, s, n);
}

typedef struct {
    const uint8_t *p;
    size_t len, at;
    int bad;
} rd_t;

static void get(rd_t *r, void *dst, size_t n)
{
    if (r->at + n > r->len) {
        r->bad = 1;
        memset(dst, 0, n);
        return;
    }
    memcpy(dst, r->p + r->at, n);
    r->at += n;
}

static uint32_t g8(rd_t *r) { uint8_t b = 0; get(r, &b, 1); return b; }
static uint32_t g16(rd_t *r) { uint16_t b = 0; get(r, &b, 2); return b; }
static uint32_t g32(rd_t *r) { uint32_t b = 0; get(r, &b, 4); return b; }
static uint64_t g64(rd_t *r) { uint64_t b = 0; get(r, &b, 8); return b; }
static double gf64(rd_t *r) { double b = 0; get(r, &b, 8); return b; }

static void gtext(rd_t *r, char *dst, size_t cap)
{
    const size_t n = g16(r);
    if (n >= cap) {
        r->bad = 1;
        dst[0] = '\0';
        return;
    }
    get(r, dst, n);
    dst[n] = '\0';
}

/* ---- framing ---------------------------------------------------------------------------------- */

static uint16_t crc16(const uint8_t *p, size_t n)
{
    uint16_t crc = 0xFFFFu; /* CRC-16/CCITT-FALSE */
    for (size_t i = 0; i < n; ++i) {
        crc ^= (uint16_t)(p[i] << 8);
        for (int b = 0; b < 8; ++b) crc = (uint16_t)((crc & 0x8000u) ? ((unsigned)crc << 1) ^ 0x1021u : (unsigned)crc << 1);
    }
    return crc;
}

static void begin(wr_t *w, pil_type_t type, uint8_t *out, size_t cap)
{
    w->p = out;
    w->len = 0;
    w->cap = cap;
    w->overflow = 0;
    u8(w, PIL_SYNC0);
    u8(w, PIL_SYNC1);
    u8(w, (uint32_t)type);
    u16(w, 0); /* the length, once known */
}

static size_t finish(wr_t *w)
{
    if (w->overflow || w->len - PIL_HEADER > PIL_MAX_PAYLOAD || w->len + 2u > w->cap) return 0;
    const uint16_t n = (uint16_t)(w->len - PIL_HEADER);
    memcpy(w->p + 3, &n, 2);
    const uint16_t crc = crc16(w->p + 2, w->len - 2u);
    u16(w, crc);
    return w->len;
}

/* ---- records ---------------------------------------------------------------------------------- */

size_t pil_encode_controller(const telem_controller_t *m, uint32_t seq, uint8_t *out, size_t cap)
{
    wr_t w;
    begin(&w, PIL_CTL, out, cap);
    u32(&w, seq);
    u64(&w, (uint64_t)m->step);
    u64(&w, (uint64_t)m->bus_period);
    f64(&w, m->t);
    u8(&w, (uint32_t)(uint8_t)m->method);
    u8(&w, (uint32_t)m->out.state);
    u8(&w, (uint32_t)m->out.fault);
    u32(&w, m->out.saturated_mask);
    u8(&w, ARM_N_JOINTS);
    f32s(&w, m->q, ARM_N_JOINTS);
    f32s(&w, m->qd, ARM_N_JOINTS);
    f32s(&w, m->q_d, ARM_N_JOINTS);
    f32s(&w, m->out.e, ARM_N_JOINTS);
    f32s(&w, m->out.e_dot, ARM_N_JOINTS);
    f32s(&w, m->out.w_hat, ARM_N_JOINTS);
    f32s(&w, m->out.u_o, ARM_N_JOINTS);
    f32s(&w, m->out.tau, ARM_N_JOINTS);
    return finish(&w);
}

size_t pil_encode_timing(const telem_timing_t *m, uint32_t seq, uint32_t step_instructions, uint8_t *out, size_t cap)
{
    wr_t w;
    begin(&w, PIL_TIMING, out, cap);
    u32(&w, seq);
    u64(&w, (uint64_t)m->step);
    u32(&w, (uint32_t)m->period_ns);
    u32(&w, (uint32_t)m->wake_latency_ns);
    u32(&w, (uint32_t)m->compute_ns);
    u32(&w, (uint32_t)m->cycle_ns);
    u64(&w, (uint64_t)m->overruns);
    u32(&w, step_instructions);
    return finish(&w);
}

size_t pil_encode_event(const telem_event_t *m, uint32_t seq, uint8_t *out, size_t cap)
{
    wr_t w;
    begin(&w, PIL_EVENT, out, cap);
    u32(&w, seq);
    u64(&w, (uint64_t)m->step);
    text(&w, m->level, sizeof(m->level));
    text(&w, m->text, sizeof(m->text));
    return finish(&w);
}

static void rx_counters(wr_t *w, const arm_rx_counters_t *c)
{
    const uint32_t v[] = {c->state, c->heartbeat, c->emcy, c->foreign_master, c->unknown_id,
                          c->bad_length, c->wrong_counter, c->bad_format, c->sim_identity, c->duplicate_state};
    for (size_t i = 0; i < sizeof(v) / sizeof(v[0]); ++i) u32(w, v[i]);
}

static void get_rx_counters(rd_t *r, arm_rx_counters_t *c)
{
    uint32_t *const v[] = {&c->state, &c->heartbeat, &c->emcy, &c->foreign_master, &c->unknown_id,
                           &c->bad_length, &c->wrong_counter, &c->bad_format, &c->sim_identity,
                           &c->duplicate_state};
    for (size_t i = 0; i < sizeof(v) / sizeof(v[0]); ++i) *v[i] = g32(r);
}

size_t pil_encode_report(const run_report_t *rep, unsigned max_writes, const pil_counts_t *c, uint8_t *out, size_t cap)
{
    wr_t w;
    begin(&w, PIL_REPORT, out, cap);
    u32(&w, (uint32_t)rep->result);
    text(&w, rep->reason, sizeof(rep->reason));
    u32(&w, rep->steps_done);
    u32(&w, rep->bus_periods);
    u64(&w, rep->frames_tx);
    u64(&w, rep->frames_rx);
    u64(&w, rep->tx_would_block);
    u64(&w, rep->rx_wrong_bus);
    u64(&w, rep->rx_undecodable);
    u64(&w, rep->rx_kernel_drops);
    u64(&w, rep->overruns);
    f64(&w, rep->wall_s);
    f64(&w, rep->boot_s);
    u32(&w, (uint32_t)rep->final_state);
    u32(&w, (uint32_t)rep->final_fault);
    rx_counters(&w, &rep->rx);
    u32(&w, (uint32_t)rep->canopen);
    f64(&w, rep->co_boot_s);
    const arm_co_fault_t *f = &rep->co_fault;
    u32(&w, (uint32_t)f->code);
    u8(&w, f->node);
    u16(&w, f->index);
    u8(&w, f->sub);
    u32(&w, f->abort_code);
    u32(&w, f->value);
    u32(&w, f->expected);
    u8(&w, f->tries);
    const unsigned writes = max_writes < rep->n_co_writes ? max_writes : rep->n_co_writes;
    u32(&w, writes);
    for (unsigned i = 0; i < writes; ++i) {
        const arm_co_write_t *x = &rep->co_writes[i];
        u8(&w, x->node);
        u16(&w, x->index);
        u8(&w, x->sub);
        u8(&w, x->len);
        u32(&w, x->value);
    }
    const run_stop_t *st = &rep->stop; /* how the arm was stopped, and which side was late */
    u32(&w, (uint32_t)st->cause);
    u32(&w, st->from_bus_period);
    u32(&w, st->periods);
    u32(&w, st->quick_stop_periods);
    u32(&w, st->stopped_mask);
    u32(&w, (uint32_t)st->braked);
    text(&w, st->safe_state, sizeof(st->safe_state));
    for (unsigned j = 0; j < ARM_N_JOINTS; ++j) u16(&w, st->statusword[j]);
    for (unsigned k = 0; k < 4u; ++k) {
        u32(&w, rep->late_count[k]);
        u32(&w, (uint32_t)rep->late_worst_us[k]);
    }
    u32(&w, (uint32_t)rep->late_side);
    text(&w, rep->late_text, sizeof(rep->late_text));
    put(&w, c, sizeof(*c)); /* all uint32_t: the same layout on both sides */
    return finish(&w);
}

/* ---- decoder ---------------------------------------------------------------------------------- */

void pil_decoder_init(pil_decoder_t *d)
{
    memset(d, 0, sizeof(*d));
}

static int decode_report(rd_t *r, run_report_t *rep, pil_counts_t *c)
{
    static run_report_t x; /* large: decoded aside, copied out only when whole */
    memset(&x, 0, sizeof(x));
    x.result = (run_result_t)g32(r);
    gtext(r, x.reason, sizeof(x.reason));
    x.steps_done = g32(r);
    x.bus_periods = g32(r);
    x.frames_tx = g64(r);
    x.frames_rx = g64(r);
    x.tx_would_block = g64(r);
    x.rx_wrong_bus = g64(r);
    x.rx_undecodable = g64(r);
    x.rx_kernel_drops = g64(r);
    x.overruns = g64(r);
    x.wall_s = gf64(r);
    x.boot_s = gf64(r);
    x.final_state = (arm_state_t)g32(r);
    x.final_fault = (arm_fault_t)g32(r);
    get_rx_counters(r, &x.rx);
    x.canopen = (int)g32(r);
    x.co_boot_s = gf64(r);
    arm_co_fault_t *f = &x.co_fault;
    f->code = (arm_co_fault_code_t)g32(r);
    f->node = (uint8_t)g8(r);
    f->index = (uint16_t)g16(r);
    f->sub = (uint8_t)g8(r);
    f->abort_code = g32(r);
    f->value = g32(r);
    f->expected = g32(r);
    f->tries = (uint8_t)g8(r);
    const uint32_t n = g32(r);
    if (n > sizeof(x.co_writes) / sizeof(x.co_writes[0])) return -1;
    x.n_co_writes = n;
    for (unsigned i = 0; i < n && !r->bad; ++i) {
        arm_co_write_t *w = &x.co_writes[i];
        w->node = (uint8_t)g8(r);
        w->index = (uint16_t)g16(r);
        w->sub = (uint8_t)g8(r);
        w->len = (uint8_t)g8(r);
        w->value = g32(r);
    }
    run_stop_t *st = &x.stop;
    st->cause = (run_stop_cause_t)g32(r);
    st->from_bus_period = g32(r);
    st->periods = g32(r);
    st->quick_stop_periods = g32(r);
    st->stopped_mask = g32(r);
    st->braked = (int)g32(r);
    gtext(r, st->safe_state, sizeof(st->safe_state));
    for (unsigned j = 0; j < ARM_N_JOINTS; ++j) st->statusword[j] = (uint16_t)g16(r);
    for (unsigned k = 0; k < 4u; ++k) {
        x.late_count[k] = g32(r);
        x.late_worst_us[k] = (int32_t)g32(r);
    }
    x.late_side = (int)g32(r);
    gtext(r, x.late_text, sizeof(x.late_text));
    pil_counts_t cc;
    get(r, &cc, sizeof(cc));
    if (r->bad || r->at != r->len) return -1;
    *rep = x;
    *c = cc;
    return 0;
}

static int decode(pil_decoder_t *d, pil_record_t *rec, run_report_t *report, pil_counts_t *counts)
{
    const uint8_t type = d->buf[2];
    uint16_t n;
    memcpy(&n, d->buf + 3, 2);
    rd_t r = {d->buf + PIL_HEADER, n, 0, 0};
    if (type == PIL_REPORT) return decode_report(&r, report, counts);
    pil_record_t x;
    memset(&x, 0, sizeof(x));
    x.type = (pil_type_t)type;
    x.seq = g32(&r);
    if (type == PIL_CTL) {
        telem_controller_t *m = &x.u.ctl;
        m->step = (int64_t)g64(&r);
        m->bus_period = (int64_t)g64(&r);
        m->t = gf64(&r);
        m->method = (int8_t)g8(&r);
        m->out.state = (arm_state_t)g8(&r);
        m->out.fault = (arm_fault_t)g8(&r);
        m->out.saturated_mask = g32(&r);
        if (g8(&r) != ARM_N_JOINTS) return -1;
        float *const arrays[] = {m->q, m->qd, m->q_d, m->out.e, m->out.e_dot, m->out.w_hat, m->out.u_o, m->out.tau};
        for (size_t i = 0; i < sizeof(arrays) / sizeof(arrays[0]); ++i) get(&r, arrays[i], 4u * ARM_N_JOINTS);
    } else if (type == PIL_TIMING) {
        telem_timing_t *m = &x.u.t.timing;
        m->step = (int64_t)g64(&r);
        m->period_ns = (int32_t)g32(&r);
        m->wake_latency_ns = (int32_t)g32(&r);
        m->compute_ns = (int32_t)g32(&r);
        m->cycle_ns = (int32_t)g32(&r);
        m->overruns = (int64_t)g64(&r);
        x.u.t.step_instructions = g32(&r);
    } else if (type == PIL_EVENT) {
        x.u.event.step = (int64_t)g64(&r);
        gtext(&r, x.u.event.level, sizeof(x.u.event.level));
        gtext(&r, x.u.event.text, sizeof(x.u.event.text));
    } else {
        return -1;
    }
    if (r.bad || r.at != r.len) return -1;
    *rec = x;
    return 1;
}

int pil_decoder_byte(pil_decoder_t *d, uint8_t byte, pil_record_t *rec, run_report_t *report, pil_counts_t *counts)
{
    if ((d->len == 0u && byte != PIL_SYNC0) || (d->len == 1u && byte != PIL_SYNC1)) {
        d->len = byte == PIL_SYNC0 ? 1u : 0u; /* between frames: wait for the sync */
        return 0;
    }
    d->buf[d->len++] = byte;
    if (d->len < PIL_HEADER) return 0;
    uint16_t n;
    memcpy(&n, d->buf + 3, 2);
    if (n > PIL_MAX_PAYLOAD) {
        d->bad++;
        d->len = 0u;
        return 0;
    }
    if (d->len < PIL_HEADER + n + 2u) return 0;
    uint16_t crc;
    memcpy(&crc, d->buf + PIL_HEADER + n, 2);
    d->len = 0u;
    if (crc != crc16(d->buf + 2, 3u + n)) {
        d->bad++;
        return 0;
    }
    const int rc = decode(d, rec, report, counts);
    if (rc < 0) {
        d->bad++;
        return 0;
    }
    d->frames++;
    if (rc == 0) rec->type = PIL_REPORT;
    return 1;
}
