#include "design_file.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LINE_CAP 4096 /* the longest line, 16 hex floats, is ~400 characters */

typedef struct {
    FILE *f;
    const char *path;
    int line;
    char buf[LINE_CAP];
    const char *key; /* the current line's field name (in buf) */
    char *rest;      /* its values */
    char *err;
    unsigned long errcap;
} reader_t;

static int fail(reader_t *r, const char *fmt, const char *field, const char *detail)
{
    char what[256];
    snprintf(what, sizeof(what), fmt, detail);
    snprintf(r->err, r->errcap, "--design-file %s:%d: %s: %s", r->path, r->line, field, what);
    return -1;
}

/* The next line that is neither empty nor a # comment, split into its field name and values. */
static int next_line(reader_t *r, const char *want)
{
    for (;;) {
        if (fgets(r->buf, sizeof(r->buf), r->f) == NULL) {
            ++r->line;
            return fail(r, "%s", want, "missing (the file ends before it)");
        }
        ++r->line;
        const size_t len = strlen(r->buf);
        if (len > 0 && r->buf[len - 1] != '\n' && !feof(r->f)) {
            return fail(r, "%s", want, "line too long");
        }
        r->buf[strcspn(r->buf, "\r\n")] = '\0';
        char *p = r->buf + strspn(r->buf, " \t");
        if (*p == '\0' || *p == '#') continue;
        r->key = p;
        p += strcspn(p, " \t");
        if (*p != '\0') *p++ = '\0';
        r->rest = p;
        if (strcmp(r->key, want) != 0) {
            char found[160];
            snprintf(found, sizeof(found), "expected here, found '%.100s'", r->key);
            return fail(r, "%s", want, found);
        }
        return 0;
    }
}

/* The next token of the values, or NULL at their end. */
static char *token(reader_t *r)
{
    char *p = r->rest + strspn(r->rest, " \t");
    if (*p == '\0') return NULL;
    char *end = p + strcspn(p, " \t");
    if (*end != '\0') *end++ = '\0';
    r->rest = end;
    return p;
}

/* Value i of the n a field must have, or NULL with the shortfall reported. */
static const char *value(reader_t *r, const char *field, int n, int i)
{
    const char *t = token(r);
    if (t == NULL) {
        char d[64];
        snprintf(d, sizeof(d), "%d values expected, found %d", n, i);
        (void)fail(r, "%s", field, d);
    }
    return t;
}

static int no_more(reader_t *r, const char *field, int n)
{
    if (token(r) != NULL) {
        char d[64];
        snprintf(d, sizeof(d), "more than the %d values expected", n);
        return fail(r, "%s", field, d);
    }
    return 0;
}

static int read_ints(reader_t *r, const char *field, int n, long long lo, long long hi, int32_t *out)
{
    if (next_line(r, field) != 0) return -1;
    for (int i = 0; i < n; ++i) {
        const char *t = value(r, field, n, i);
        if (t == NULL) return -1;
        char *end = NULL;
        errno = 0;
        const long long v = strtoll(t, &end, 10);
        if (errno != 0 || end == t || *end != '\0' || v < lo || v > hi) {
            char d[160];
            snprintf(d, sizeof(d), "value %d '%.40s' is not an integer in [%lld, %lld]", i + 1, t, lo, hi);
            return fail(r, "%s", field, d);
        }
        out[i] = (int32_t)v;
    }
    return no_more(r, field, n);
}

static int read_int(reader_t *r, const char *field, long long lo, long long hi, int *out)
{
    int32_t v = 0;
    if (read_ints(r, field, 1, lo, hi, &v) != 0) return -1;
    *out = (int)v;
    return 0;
}

static int read_floats(reader_t *r, const char *field, int n, float *out)
{
    if (next_line(r, field) != 0) return -1;
    for (int i = 0; i < n; ++i) {
        const char *t = value(r, field, n, i);
        if (t == NULL) return -1;
        char *end = NULL;
        const float v = strtof(t, &end); /* C99 hex floats are read exactly */
        if (end == t || *end != '\0' || !isfinite(v)) {
            char d[160];
            snprintf(d, sizeof(d), "value %d '%.40s' is not a finite number", i + 1, t);
            return fail(r, "%s", field, d);
        }
        out[i] = v;
    }
    return no_more(r, field, n);
}

static int read_dim(reader_t *r, const char *field, int max, const char *max_name, int *out)
{
    if (read_int(r, field, 0, 1000000, out) != 0) return -1;
    if (*out < 1 || *out > max) {
        char d[160];
        snprintf(d, sizeof(d), "%d states; this build runs 1 to %d (%s)", *out, max, max_name);
        return fail(r, "%s", field, d);
    }
    return 0;
}

static int parse(reader_t *r, design_file_t *o)
{
    arm_pm_design_t *d = &o->d;
    if (next_line(r, "arm-pm-design") != 0) return -1;
    if (strcmp(r->rest, "1") != 0) return fail(r, "%s", "arm-pm-design", "format version is not 1");
    if (next_line(r, "hash") != 0) return -1;
    const char *h = token(r);
    if (h == NULL || strlen(h) != 16 || strspn(h, "0123456789abcdef") != 16) {
        return fail(r, "%s", "hash", "not 16 lower-case hex digits");
    }
    memcpy(d->hash, h, 17);
    if (no_more(r, "hash", 1) != 0) return -1;
    if (read_int(r, "n_joints", 0, 1000000, &d->n_joints) != 0) return -1;
    if (d->n_joints != ARM_N_JOINTS) {
        char m[128];
        snprintf(m, sizeof(m), "%d joints; this build's arm has %d", d->n_joints, ARM_N_JOINTS);
        return fail(r, "%s", "n_joints", m);
    }
    float rate = 0.0f;
    if (read_floats(r, "loop_rate_hz", 1, &rate) != 0) return -1;
    if (!(rate > 0.0f)) return fail(r, "%s", "loop_rate_hz", "not > 0");
    d->loop_rate_hz = rate;
    if (read_dim(r, "est_nx", ARM_PM_EST_NX_MAX, "ARM_PM_EST_NX_MAX", &d->est_nx) != 0) return -1;
    if (read_dim(r, "ctl_nx", ARM_PM_CTL_NX_MAX, "ARM_PM_CTL_NX_MAX", &d->ctl_nx) != 0) return -1;
    const int ne = d->est_nx, nc = d->ctl_nx;
    if (read_floats(r, "est_a", ne * ne, o->est_a) || read_floats(r, "est_b", ne * 2, o->est_b) ||
        read_floats(r, "est_c", ne, o->est_c) || read_floats(r, "est_d", 2, o->est_d) ||
        read_floats(r, "ctl_a", nc * nc, o->ctl_a) || read_floats(r, "ctl_b", nc * 2, o->ctl_b) ||
        read_floats(r, "ctl_c", nc, o->ctl_c) || read_floats(r, "ctl_d", 2, o->ctl_d) ||
        read_floats(r, "im_a", 4, o->im_a) || read_floats(r, "im_b", 2, o->im_b)) {
        return -1;
    }
    /* 0..62: 1LL << f and the rounding term 1 << (shift - 1) stay defined */
    if (read_int(r, "y_frac", 0, 62, &d->y_frac) || read_int(r, "est_u_frac", 0, 62, &d->est_u_frac) ||
        read_int(r, "ctl_u_frac", 0, 62, &d->ctl_u_frac) ||
        read_int(r, "est_acc_x_shift", 0, 62, &d->est_acc_x_shift) ||
        read_int(r, "est_acc_u_shift", 0, 62, &d->est_acc_u_shift) ||
        read_int(r, "ctl_acc_x_shift", 0, 62, &d->ctl_acc_x_shift) ||
        read_int(r, "ctl_acc_u_shift", 0, 62, &d->ctl_acc_u_shift) ||
        read_int(r, "im_acc_x_shift", 0, 62, &d->im_acc_x_shift)) {
        return -1;
    }
    const long long imax = 2147483647LL;
    if (read_ints(r, "range_e_max_q", 1, 1, imax, &d->range_e_max_q) ||
        read_ints(r, "range_e_dot_max_q", 1, 1, imax, &d->range_e_dot_max_q) ||
        read_ints(r, "im_e_max_q", 1, 1, imax, &d->im_e_max_q) ||
        read_ints(r, "im_e_dot_max_q", 1, 1, imax, &d->im_e_dot_max_q)) {
        return -1;
    }
    if (read_ints(r, "est_a_q", ne * ne, -imax, imax, o->est_a_q) ||
        read_ints(r, "est_b_q", ne * 2, -imax, imax, o->est_b_q) ||
        read_ints(r, "est_c_q", ne, -imax, imax, o->est_c_q) || read_ints(r, "est_d_q", 2, -imax, imax, o->est_d_q) ||
        read_ints(r, "ctl_a_q", nc * nc, -imax, imax, o->ctl_a_q) ||
        read_ints(r, "ctl_b_q", nc * 2, -imax, imax, o->ctl_b_q) ||
        read_ints(r, "ctl_c_q", nc, -imax, imax, o->ctl_c_q) || read_ints(r, "ctl_d_q", 2, -imax, imax, o->ctl_d_q) ||
        read_ints(r, "im_a_q", 4, -imax, imax, o->im_a_q) || read_ints(r, "im_b_q", 2, -imax, imax, o->im_b_q)) {
        return -1;
    }
    if (next_line(r, "end") != 0) return -1;
    for (;;) { /* nothing but comments after it */
        if (fgets(r->buf, sizeof(r->buf), r->f) == NULL) break;
        ++r->line;
        const char *p = r->buf + strspn(r->buf, " \t\r\n");
        if (*p != '\0' && *p != '#') return fail(r, "%s", "end", "something follows it");
    }
    d->est_a = o->est_a, d->est_b = o->est_b, d->est_c = o->est_c, d->est_d = o->est_d;
    d->ctl_a = o->ctl_a, d->ctl_b = o->ctl_b, d->ctl_c = o->ctl_c, d->ctl_d = o->ctl_d;
    d->im_a = o->im_a, d->im_b = o->im_b;
    d->est_a_q = o->est_a_q, d->est_b_q = o->est_b_q, d->est_c_q = o->est_c_q, d->est_d_q = o->est_d_q;
    d->ctl_a_q = o->ctl_a_q, d->ctl_b_q = o->ctl_b_q, d->ctl_c_q = o->ctl_c_q, d->ctl_d_q = o->ctl_d_q;
    d->im_a_q = o->im_a_q, d->im_b_q = o->im_b_q;
    return 0;
}

int design_file_load(const char *path, design_file_t *out, char *err, unsigned long errcap)
{
    static reader_t r; /* its line buffer is large: not on the stack */
    memset(&r, 0, sizeof(r));
    memset(out, 0, sizeof(*out));
    snprintf(out->path, sizeof(out->path), "%s", path);
    r.path = path;
    r.err = err;
    r.errcap = errcap;
    r.f = fopen(path, "r");
    if (r.f == NULL) {
        snprintf(err, errcap, "--design-file %s: cannot open it: %s", path, strerror(errno));
        return -1;
    }
    const int rc = parse(&r, out);
    fclose(r.f);
    if (rc == 0 && arm_pm_design_fits(&out->d) != 0) {
        snprintf(err, errcap, "--design-file %s: the design does not fit this build", path);
        return -1;
    }
    return rc;
}
