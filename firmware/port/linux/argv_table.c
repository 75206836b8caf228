#include "argv_table.h"

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int argv_double(const char *name, const char *s, double lo, double hi, int lo_open, double *out, char *err,
                unsigned long errcap)
{
    char *end = NULL;
    errno = 0;
    const double v = strtod(s, &end);
    if (errno != 0 || end == s || *end != '\0' || !isfinite(v) || v < lo || v > hi || (lo_open && v <= lo)) {
        snprintf(err, errcap, "%s: '%s' is not a number in %s%g, %g]", name, s, lo_open ? "(" : "[", lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

int argv_whole(const char *name, const char *s, double lo, double hi, double *out, char *err,
               unsigned long errcap)
{
    if (argv_double(name, s, lo, hi, 0, out, err, errcap) != 0) return -1;
    if (*out != floor(*out)) {
        snprintf(err, errcap, "%s: '%s' is not a whole number", name, s);
        return -1;
    }
    return 0;
}

int argv_copy(const char *name, const char *s, char *dst, size_t cap, char *err, unsigned long errcap)
{
    if (strlen(s) >= cap) {
        snprintf(err, errcap, "%s: value longer than %zu characters", name, cap - 1u);
        return -1;
    }
    memcpy(dst, s, strlen(s) + 1u);
    return 0;
}

/* An int-like member as wide as it is: an enum is one byte where the ABI makes it the smallest that
 * holds its values (arm-none-eabi's short enums: the MCU image parses these options too). */
static void store_int(void *p, size_t size, int v)
{
    if (size == sizeof(int8_t)) {
        const int8_t b = (int8_t)v;
        memcpy(p, &b, sizeof(b));
    } else if (size == sizeof(int16_t)) {
        const int16_t h = (int16_t)v;
        memcpy(p, &h, sizeof(h));
    } else {
        memcpy(p, &v, sizeof(v));
    }
}

static void store(const argv_opt_t *o, void *target, double v)
{
    char *p = (char *)target + o->offset;
    switch (o->kind) {
    case ARGV_DOUBLE: *(double *)(void *)p = v * o->scale; break;
    case ARGV_FLOAT: *(float *)(void *)p = (float)(v * o->scale); break;
    case ARGV_FLOATS:
        for (size_t j = 0; j < o->size / sizeof(float); ++j) ((float *)(void *)p)[j] = (float)(v * o->scale);
        break;
    case ARGV_UINT32: *(uint32_t *)(void *)p = (uint32_t)v; break;
    case ARGV_INT:
    case ARGV_FLAG:
    case ARGV_CHOICE: store_int(p, o->size, (int)v); break;
    case ARGV_LONG: *(long *)(void *)p = (long)v; break;
    case ARGV_TEXT:
    case ARGV_SPECIAL: break;
    }
}

void argv_defaults(const argv_opt_t *table, size_t n, void *target)
{
    for (size_t i = 0; i < n; ++i) {
        if (table[i].has_default) store(&table[i], target, table[i].def);
    }
}

static int parse_one(const argv_opt_t *o, const char *v, void *target, void *ctx, char *err, unsigned long errcap)
{
    double d = 0.0;
    switch (o->kind) {
    case ARGV_SPECIAL: return o->handler(target, ctx, o, v, err, errcap);
    case ARGV_CHOICE: {
        size_t k = 0, len = 0;
        while (o->choices[k] != NULL && strcmp(o->choices[k], v) != 0) ++k;
        if (o->choices[k] != NULL) {
            store(o, target, (double)k);
            return 0;
        }
        /* "'x' is not a, b or c" */
        len = (size_t)snprintf(err, errcap, "%s: '%s' is not ", o->name, v);
        for (k = 0; o->choices[k] != NULL && len < errcap; ++k) {
            const char *sep = k == 0 ? "" : o->choices[k + 1] == NULL ? " or " : ", ";
            len += (size_t)snprintf(err + len, errcap - len, "%s%s", sep, o->choices[k]);
        }
        return -1;
    }
    case ARGV_TEXT: return argv_copy(o->name, v, (char *)target + o->offset, o->size, err, errcap);
    case ARGV_UINT32:
    case ARGV_INT:
    case ARGV_LONG:
        if (argv_whole(o->name, v, o->lo, o->hi, &d, err, errcap) != 0) return -1;
        break;
    case ARGV_DOUBLE:
    case ARGV_FLOAT:
    case ARGV_FLOATS:
    case ARGV_FLAG:
        if (argv_double(o->name, v, o->lo, o->hi, o->lo_open, &d, err, errcap) != 0) return -1;
        break;
    }
    store(o, target, d);
    return 0;
}

int argv_parse(int argc, char **argv, const argv_opt_t *table, size_t n, void *target, void *ctx,
               unsigned char *given, char *err, unsigned long errcap)
{
    memset(given, 0, n);
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) return 1;
        size_t k = 0;
        while (k < n && strcmp(table[k].name, a) != 0) ++k;
        if (k < n && table[k].kind == ARGV_FLAG) {
            store(&table[k], target, 1.0);
            given[k] = 1u;
            continue;
        }
        if (strncmp(a, "--", 2) != 0) {
            snprintf(err, errcap, "unexpected argument '%s' (options start with --)", a);
            return -1;
        }
        if (i + 1 >= argc) {
            snprintf(err, errcap, "%s: missing value", a);
            return -1;
        }
        const char *v = argv[++i];
        if (k == n) {
            snprintf(err, errcap, "unknown option '%s' (see --help)", a);
            return -1;
        }
        if (parse_one(&table[k], v, target, ctx, err, errcap) != 0) return -1;
        given[k] = 1u;
    }
    return 0;
}
