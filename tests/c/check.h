/* A minimal test harness: CHECK records failures and keeps going; TEST_MAIN_END prints the
 * "N passed, N failed" line that CI reads and sets the exit code (non-zero on a failure, or when
 * no check ran at all). */
#ifndef ARM_TEST_CHECK_H
#define ARM_TEST_CHECK_H

#include <stdio.h>

static int g_checks_passed;
static int g_checks_failed;

/* Counts one check; a failure is reported as file:line and the condition's text, then `tail`. */
static inline int check_record(int ok, const char *file, int line, const char *cond, const char *tail)
{
    if (ok) {
        ++g_checks_passed;
        return 1;
    }
    ++g_checks_failed;
    fprintf(stderr, "%s:%d: CHECK failed: %s%s", file, line, cond, tail);
    return 0;
}

#define CHECK(cond)                                                                     \
    do {                                                                                \
        (void)check_record((cond) ? 1 : 0, __FILE__, __LINE__, #cond, "\n");           \
    } while (0)

#define CHECK_MSG(cond, ...)                                                            \
    do {                                                                                \
        if (!check_record((cond) ? 1 : 0, __FILE__, __LINE__, #cond, ": ")) {           \
            fprintf(stderr, __VA_ARGS__);                                               \
            fputc('\n', stderr);                                                        \
        }                                                                               \
    } while (0)

/* A binary that ran no check proved nothing: it fails too (a test whose checks were skipped or
 * never reached, e.g. by an early return, is not a pass). */
#define TEST_MAIN_END()                                                                 \
    do {                                                                                \
        printf("%d passed, %d failed\n", g_checks_passed, g_checks_failed);             \
        if (g_checks_passed + g_checks_failed == 0) {                                   \
            fprintf(stderr, "no check ran: a test that checks nothing fails\n");        \
        }                                                                               \
        return g_checks_failed == 0 && g_checks_passed > 0 ? 0 : 1;                     \
    } while (0)

#endif
