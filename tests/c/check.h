/* A minimal test harness: CHECK records failures and keeps going; TEST_MAIN_END prints the
 * "N passed, N failed" line that CI reads and sets the exit code. */
#ifndef ARM_TEST_CHECK_H
#define ARM_TEST_CHECK_H

#include <stdio.h>

static int g_checks_passed;
static int g_checks_failed;

#define CHECK(cond)                                                                     \
    do {                                                                                \
        if (cond) {                                                                     \
            ++g_checks_passed;                                                          \
        } else {                                                                        \
            ++g_checks_failed;                                                          \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);   \
        }                                                                               \
    } while (0)

#define CHECK_MSG(cond, ...)                                                            \
    do {                                                                                \
        if (cond) {                                                                     \
            ++g_checks_passed;                                                          \
        } else {                                                                        \
            ++g_checks_failed;                                                          \
            fprintf(stderr, "%s:%d: CHECK failed: %s: ", __FILE__, __LINE__, #cond);   \
            fprintf(stderr, __VA_ARGS__);                                               \
            fputc('\n', stderr);                                                        \
        }                                                                               \
    } while (0)

#define TEST_MAIN_END()                                                                 \
    do {                                                                                \
        printf("%d passed, %d failed\n", g_checks_passed, g_checks_failed);             \
        return g_checks_failed == 0 ? 0 : 1;                                            \
    } while (0)

#endif
