/* The one argv parser of arm_controller and arm_sim (and arm_sil, which runs both), driven by an
 * option table: the X-macro ARM_<PROGRAM>_OPTIONS of the generated arm_params.h (from the
 * registry firmware/params/params.toml), expanded over the program's options struct. Every error
 * is one line naming the option and the value. */
#ifndef ARM_ARGV_TABLE_H
#define ARM_ARGV_TABLE_H

#include <stddef.h>

#include "arm_params.h"

typedef enum {
    ARGV_DOUBLE,  /* double, times scale */
    ARGV_FLOAT,   /* float, times scale */
    ARGV_FLOATS,  /* every element of a float array */
    ARGV_UINT32,  /* whole numbers */
    ARGV_INT,
    ARGV_LONG,
    ARGV_TEXT,    /* a char array */
    ARGV_FLAG,    /* an int set to 1; takes no value */
    ARGV_CHOICE,  /* one of choices: its index into an int-sized enum */
    ARGV_SPECIAL  /* the program's handler */
} argv_kind_t;

struct argv_opt;
/* A special option's handler: value v of option o (o->name) into target; ctx is the program's. */
typedef int (*argv_handler_t)(void *target, void *ctx, const struct argv_opt *o, const char *v, char *err,
                              unsigned long errcap);

typedef struct argv_opt {
    const char *name;
    argv_kind_t kind;
    double lo, hi;
    int lo_open;
    double scale;
    double def;
    int has_default;
    size_t offset, size; /* the member in the target */
    const char *const *choices; /* ARGV_CHOICE: the words, NULL-terminated */
    argv_handler_t handler;
} argv_opt_t;

/* One row per registry entry: ARM_<PROGRAM>_OPTIONS(ARGV_ROW_OF(type), ARGV_SPECIAL_ROW). */
#define ARGV_ROW(T, id, name, kind, lo, hi, lo_open, scale, def, has_def, member, choices)                    \
    {name, kind, lo, hi, lo_open, scale, def, has_def, offsetof(T, member), sizeof(((T *)0)->member), choices, \
     NULL},
#define ARGV_SPECIAL_ROW(id, name, handler) {name, ARGV_SPECIAL, 0.0, 0.0, 0, 1.0, 0.0, 0, 0u, 0u, NULL, handler},
#define ARGV_ID(id, ...) ARGV_OPT_##id,

/* The table's numeric defaults into target. */
void argv_defaults(const argv_opt_t *table, size_t n, void *target);
/* argv[1..] into target; given[i] = 1 for each row i given. 0: parsed; 1: --help or -h (the caller
 * prints its usage); -1: bad argument, the message in err. */
int argv_parse(int argc, char **argv, const argv_opt_t *table, size_t n, void *target, void *ctx,
               unsigned char *given, char *err, unsigned long errcap);

/* For handlers: a finite number in [lo, hi] ((lo, hi] if lo_open), a whole one, a copy. */
int argv_double(const char *name, const char *s, double lo, double hi, int lo_open, double *out, char *err,
                unsigned long errcap);
int argv_whole(const char *name, const char *s, double lo, double hi, double *out, char *err,
               unsigned long errcap);
int argv_copy(const char *name, const char *s, char *dst, size_t cap, char *err, unsigned long errcap);

#endif
