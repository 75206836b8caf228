#define _POSIX_C_SOURCE 200809L
#include "sim_canopen_od.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define TABLE_MAGIC "arm_sim od 1" /* gen/eds.py TABLE_MAGIC */

/* ---- the table: gen/eds.py table_text, one line per entry ------------------------------------ */
static int hex_u64(const char *s, uint64_t *out)
{
    char *end = NULL;
    errno = 0;
    const unsigned long long v = strtoull(s, &end, 16);
    if (errno != 0 || end == s || *end != '\0' || s[0] == '-') return -1;
    *out = (uint64_t)v;
    return 0;
}

static int hex_bytes(sim_co_table_t *t, const char *s, sim_co_entry_t *e)
{
    e->text_off = t->text_len;
    e->text_len = 0u;
    if (strcmp(s, "-") == 0) return 0;
    const size_t n = strlen(s);
    if (n % 2u != 0u || n / 2u > SIM_CO_TEXT_MAX - t->text_len) return -1;
    for (size_t k = 0; k < n; k += 2u) {
        char two[3] = {s[k], s[k + 1u], '\0'};
        char *end = NULL;
        const unsigned long b = strtoul(two, &end, 16);
        if (end != two + 2) return -1;
        t->text[t->text_len++] = (uint8_t)b;
    }
    e->text_len = (uint32_t)(n / 2u);
    return 0;
}

static int parse_line(sim_co_table_t *t, char *line, sim_co_entry_t *e)
{
    char *f[11];
    unsigned n = 0;
    char *save = NULL;
    for (char *tok = strtok_r(line, " ", &save); tok != NULL && n < 11u; tok = strtok_r(NULL, " ", &save)) f[n++] = tok;
    if (n != 11u || strtok_r(NULL, " ", &save) != NULL) return -1;
    uint64_t v[8];
    for (unsigned k = 0; k < 8u; ++k) {
        if (hex_u64(f[k], &v[k]) != 0) return -1;
    }
    if (v[0] > 0xFFFFu || v[1] > 0xFFu || v[2] < 1u || v[2] > 0x1Bu || v[3] > SIM_CO_K_BYTES || v[4] > 8u ||
        v[5] > SIM_CO_A_RWR || v[6] > 1u || v[7] > 1u) {
        return -1;
    }
    *e = (sim_co_entry_t){.index = (uint16_t)v[0], .sub = (uint8_t)v[1], .type = (uint8_t)v[2], .kind = (uint8_t)v[3],
                          .size = (uint8_t)v[4], .access = (uint8_t)v[5], .pdo = (uint8_t)v[6],
                          .nodeid_rel = (uint8_t)v[7]};
    const int string = e->kind == SIM_CO_K_TEXT || e->kind == SIM_CO_K_BYTES;
    if (string != (e->size == 0u)) return -1;
    if (string) return hex_bytes(t, f[8], e);
    if (hex_u64(f[8], &e->def) != 0) return -1;
    e->has_low = strcmp(f[9], "-") != 0;
    e->has_high = strcmp(f[10], "-") != 0;
    if ((e->has_low && hex_u64(f[9], &e->low) != 0) || (e->has_high && hex_u64(f[10], &e->high) != 0)) return -1;
    return 0;
}

static unsigned hash_of(uint32_t key)
{
    return (key * 2654435761u) >> (32u - SIM_CO_HASH_BITS); /* Knuth's multiplicative hash */
}

static void index_rows(sim_co_table_t *t)
{
    memset(t->slot, 0, sizeof(t->slot));
    for (unsigned i = 0; i < t->n; ++i) {
        unsigned h = hash_of(t->key[i]);
        while (t->slot[h] != 0u) h = (h + 1u) & (SIM_CO_HASH_SLOTS - 1u);
        t->slot[h] = (uint16_t)(i + 1u);
    }
}

int sim_co_table_parse(sim_co_table_t *t, const char *text, char *err, size_t cap)
{
    t->n = 0u;
    t->text_len = 0u;
    unsigned line_no = 0u, declared = 0u;
    for (const char *p = text; *p != '\0';) {
        const char *nl = strchr(p, '\n');
        const size_t len = nl != NULL ? (size_t)(nl - p) : strlen(p);
        char line[1024];
        ++line_no;
        if (len >= sizeof(line)) {
            snprintf(err, cap, "line %u: longer than %zu characters", line_no, sizeof(line) - 1u);
            return -1;
        }
        memcpy(line, p, len);
        line[len] = '\0';
        p += len + (nl != NULL ? 1u : 0u);
        if (line_no == 1u) {
            char tail = 0;
            if (strncmp(line, TABLE_MAGIC " ", sizeof(TABLE_MAGIC)) != 0 ||
                sscanf(line + sizeof(TABLE_MAGIC), "%u%c", &declared, &tail) != 1) {
                snprintf(err, cap, "line 1: not an object dictionary table of gen/eds.py ('%s N')", TABLE_MAGIC);
                return -1;
            }
            if (declared == 0u || declared > SIM_CO_OD_MAX) {
                snprintf(err, cap, "line 1: %u entries (1..%u)", declared, SIM_CO_OD_MAX);
                return -1;
            }
            continue;
        }
        if (t->n == declared) {
            snprintf(err, cap, "line %u: more entries than the %u line 1 declares", line_no, declared);
            return -1;
        }
        sim_co_entry_t *e = &t->e[t->n];
        if (parse_line(t, line, e) != 0) {
            snprintf(err, cap, "line %u: not 'index sub type kind size access pdo rel value low high' (hex), or "
                     "out of range", line_no);
            return -1;
        }
        if (t->n > 0u) {
            const sim_co_entry_t *prev = &t->e[t->n - 1u];
            if (((uint32_t)prev->index << 8 | prev->sub) >= ((uint32_t)e->index << 8 | e->sub)) {
                snprintf(err, cap, "line %u: 0x%04X:%02X is not after 0x%04X:%02X (the table is sorted)", line_no,
                         e->index, e->sub, prev->index, prev->sub);
                return -1;
            }
        }
        t->key[t->n] = (uint32_t)e->index << 8 | e->sub;
        t->n++;
    }
    if (t->n != declared) {
        snprintf(err, cap, "%u entries, line 1 declares %u", t->n, declared);
        return -1;
    }
    index_rows(t);
    return 0;
}

int sim_co_table_load(sim_co_table_t *t, const char *path, char *err, size_t cap)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        snprintf(err, cap, "%s: %s", path, strerror(errno));
        return -1;
    }
    static char buf[SIM_CO_OD_MAX * 96u + 2u * SIM_CO_TEXT_MAX + 64u];
    const size_t n = fread(buf, 1u, sizeof(buf) - 1u, f);
    const int too_long = n == sizeof(buf) - 1u && fgetc(f) != EOF;
    fclose(f);
    if (too_long) {
        snprintf(err, cap, "%s: larger than %zu bytes", path, sizeof(buf) - 1u);
        return -1;
    }
    buf[n] = '\0';
    if (strlen(buf) != n) {
        snprintf(err, cap, "%s: not a text table (a NUL byte)", path);
        return -1;
    }
    char why[300];
    if (sim_co_table_parse(t, buf, why, sizeof(why)) != 0) {
        snprintf(err, cap, "%s: %s", path, why);
        return -1;
    }
    return 0;
}

const sim_co_table_t *sim_co_table_builtin(void)
{
    static sim_co_table_t table;
    static int state; /* 0 not parsed, 1 parsed, -1 broken */
    if (state == 0) {
        char err[300];
        state = sim_co_table_parse(&table, SIM_CO_OD_BUILTIN, err, sizeof(err)) == 0 ? 1 : -1;
    }
    return state == 1 ? &table : NULL;
}

int sim_co_table_find(const sim_co_table_t *t, uint16_t index, uint8_t sub, uint32_t *abort_code)
{
    const uint32_t key = (uint32_t)index << 8 | sub;
    for (unsigned h = hash_of(key); t->slot[h] != 0u; h = (h + 1u) & (SIM_CO_HASH_SLOTS - 1u)) {
        if (t->key[t->slot[h] - 1u] == key) return (int)t->slot[h] - 1;
    }
    /* not there: which abort, no object or no sub-index, from the rows around where it would be */
    unsigned lo = 0u, hi = t->n;
    while (lo < hi) { /* the first row at or after key */
        const unsigned mid = lo + (hi - lo) / 2u;
        if (t->key[mid] < key) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if (lo < t->n && t->e[lo].index == index && t->e[lo].sub == sub) return (int)lo;
    /* the object is there if a row of it sits around where (index, sub) would be */
    const int seen = (lo < t->n && t->e[lo].index == index) || (lo > 0u && t->e[lo - 1u].index == index);
    *abort_code = seen ? SIM_CO_ABORT_NO_SUB : SIM_CO_ABORT_NO_OBJECT;
    return -1;
}

/* ---- one node's values ----------------------------------------------------------------------- */
static uint64_t size_mask(const sim_co_entry_t *e)
{
    return e->size >= 8u ? ~(uint64_t)0 : (((uint64_t)1 << (8u * e->size)) - 1u);
}

void sim_co_od_reset(sim_co_od_t *od, const sim_co_table_t *t, uint8_t node_id, int comm_only)
{
    od->t = t;
    od->node_id = node_id;
    if (!comm_only) od->n_str = 0u;
    for (unsigned i = 0; i < t->n; ++i) {
        const sim_co_entry_t *e = &t->e[i];
        if (comm_only && (e->index < 0x1000u || e->index > 0x1FFFu)) continue;
        od->value[i] = e->size == 0u ? 0u : ((e->def + (e->nodeid_rel ? node_id : 0u)) & size_mask(e));
    }
}

int sim_co_od_find(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint32_t *abort_code)
{
    return sim_co_table_find(od->t, index, sub, abort_code);
}

int sim_co_od_has(const sim_co_od_t *od, uint16_t index, uint8_t sub)
{
    uint32_t ab;
    return sim_co_od_find(od, index, sub, &ab) >= 0;
}

uint64_t sim_co_od_get(const sim_co_od_t *od, uint16_t index, uint8_t sub)
{
    uint32_t ab;
    const int i = sim_co_od_find(od, index, sub, &ab);
    return i < 0 || od->t->e[i].size == 0u ? 0u : od->value[i];
}

static int64_t as_signed(const sim_co_entry_t *e, uint64_t raw)
{
    if (e->kind != SIM_CO_K_INT || e->size >= 8u) return (int64_t)raw;
    const uint64_t sign = (uint64_t)1 << (8u * e->size - 1u);
    return (int64_t)((raw ^ sign) - sign);
}

int64_t sim_co_od_get_signed(const sim_co_od_t *od, uint16_t index, uint8_t sub)
{
    uint32_t ab;
    const int i = sim_co_od_find(od, index, sub, &ab);
    return i < 0 ? 0 : as_signed(&od->t->e[i], od->value[i]);
}

void sim_co_od_set(sim_co_od_t *od, uint16_t index, uint8_t sub, uint64_t raw)
{
    uint32_t ab;
    const int i = sim_co_od_find(od, index, sub, &ab);
    if (i >= 0 && od->t->e[i].size != 0u) od->value[i] = raw & size_mask(&od->t->e[i]);
}

uint32_t sim_co_od_read(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap,
                        unsigned *len)
{
    uint32_t ab = 0;
    const int i = sim_co_od_find(od, index, sub, &ab);
    if (i < 0) return ab;
    const sim_co_entry_t *e = &od->t->e[i];
    if (e->access == SIM_CO_A_WO) return SIM_CO_ABORT_WRITE_ONLY;
    if (e->size == 0u) {
        const uint64_t slot = od->value[i];
        const uint8_t *src = slot == 0u ? &od->t->text[e->text_off] : od->str[slot - 1u];
        const unsigned n = slot == 0u ? e->text_len : od->str_len[slot - 1u];
        if (n > cap) return SIM_CO_ABORT_LENGTH;
        memcpy(buf, src, n);
        *len = n;
        return 0u;
    }
    if (e->size > cap) return SIM_CO_ABORT_LENGTH;
    for (unsigned k = 0; k < e->size; ++k) buf[k] = (uint8_t)(od->value[i] >> (8u * k));
    *len = e->size;
    return 0u;
}

static double as_float(const sim_co_entry_t *e, uint64_t raw)
{
    if (e->size == 4u) {
        float f;
        const uint32_t b = (uint32_t)raw;
        memcpy(&f, &b, sizeof(f));
        return (double)f;
    }
    double d;
    memcpy(&d, &raw, sizeof(d));
    return d;
}

/* 1 if raw is below the entry's low limit (which < 0) or above its high limit (which > 0). */
static int beyond(const sim_co_entry_t *e, uint64_t raw, uint64_t limit, int which)
{
    switch (e->kind) {
    case SIM_CO_K_INT: {
        const int64_t x = as_signed(e, raw), l = as_signed(e, limit);
        return which < 0 ? x < l : x > l;
    }
    case SIM_CO_K_FLOAT: {
        const double x = as_float(e, raw), l = as_float(e, limit);
        return x != x || (which < 0 ? x < l : x > l); /* NaN is in no range */
    }
    default:
        return which < 0 ? raw < limit : raw > limit;
    }
}

uint32_t sim_co_od_check_write(sim_co_od_t *od, uint16_t index, uint8_t sub, const uint8_t *data, unsigned len,
                               uint64_t *raw, int *is_string)
{
    uint32_t ab = 0;
    const int i = sim_co_od_find(od, index, sub, &ab);
    if (i < 0) return ab;
    const sim_co_entry_t *e = &od->t->e[i];
    *is_string = e->size == 0u;
    if (e->access == SIM_CO_A_RO || e->access == SIM_CO_A_CONST) return SIM_CO_ABORT_READ_ONLY;
    if (e->size == 0u) { /* a string or domain: kept in one of the node's slots */
        if (len > SIM_CO_VALUE_MAX) return SIM_CO_ABORT_LENGTH;
        uint64_t slot = od->value[i];
        if (slot == 0u) {
            if (od->n_str == SIM_CO_STR_SLOTS) return SIM_CO_ABORT_NO_MEMORY;
            slot = ++od->n_str;
        }
        memcpy(od->str[slot - 1u], data, len);
        od->str_len[slot - 1u] = (uint16_t)len;
        od->value[i] = slot;
        return 0u;
    }
    if (len != e->size) return SIM_CO_ABORT_LENGTH;
    uint64_t v = 0;
    for (unsigned k = 0; k < len; ++k) v |= (uint64_t)data[k] << (8u * k);
    if (e->kind == SIM_CO_K_BOOL && v > 1u) return SIM_CO_ABORT_RANGE;
    if ((e->has_low && beyond(e, v, e->low, -1)) || (e->has_high && beyond(e, v, e->high, 1)) ||
        (e->kind == SIM_CO_K_FLOAT && as_float(e, v) != as_float(e, v))) {
        return SIM_CO_ABORT_RANGE;
    }
    *raw = v;
    return 0u;
}
