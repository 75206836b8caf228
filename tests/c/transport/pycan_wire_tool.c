/*
 * CLI around the codec so Python can cross-check it against python-can.
 *
 *   pycan_wire_tool encode ID LEN HEXDATA FLAGS [TIMESTAMP]  -> datagram hex
 *   pycan_wire_tool decode HEX            -> "0xID LEN 0xFLAGS HEXDATA TIMESTAMP"
 *   pycan_wire_tool batch                 -> one command per stdin line, one answer per line
 *
 * HEXDATA "-" is empty; FLAGS are ARM_CAN_FLAG_* bits (C integer syntax).
 * Errors print "error <name>" (exit 2 in single-shot mode); TIMESTAMP is
 * printed with %.17g so it round-trips exactly.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/pycan_wire.h"
#include "frame_text.h"

#define MAX_DATAGRAM 4096u
#define EXIT_USAGE 64
#define EXIT_CODEC 2

static int parse_ulong(const char *s, unsigned long max, unsigned long *out)
{
    char *end = NULL;
    errno = 0;
    const unsigned long v = strtoul(s, &end, 0);
    if (errno != 0 || end == s || *end != '\0' || v > max || s[0] == '-') {
        return -1;
    }
    *out = v;
    return 0;
}

/* Returns 0 ok, EXIT_CODEC codec error, EXIT_USAGE bad arguments. */
static int do_encode(int argc, char **argv)
{
    if (argc < 4 || argc > 5) {
        return EXIT_USAGE;
    }
    unsigned long id, len, flags;
    arm_can_frame_t f;
    memset(&f, 0, sizeof f);
    size_t ndata;
    if (parse_ulong(argv[0], 0xFFFFFFFFul, &id) != 0 || parse_ulong(argv[1], 255ul, &len) != 0 ||
        parse_ulong(argv[3], 255ul, &flags) != 0 ||
        frame_text_parse_hex(argv[2], f.data, sizeof f.data, &ndata) != 0) {
        return EXIT_USAGE;
    }
    double ts = 0.0;
    if (argc == 5) {
        char *end = NULL;
        ts = strtod(argv[4], &end);
        if (end == argv[4] || *end != '\0') {
            return EXIT_USAGE;
        }
    }
    f.id = (uint32_t)id;
    f.len = (uint8_t)len;
    f.flags = (uint8_t)flags;
    uint8_t out[ARM_PYCAN_MAX_ENCODED];
    const size_t n = arm_pycan_encode(&f, ts, out, sizeof out);
    if (n == 0u) {
        printf("error encode\n");
        return EXIT_CODEC;
    }
    frame_text_hex(stdout, out, n);
    putchar('\n');
    return 0;
}

static int do_decode(int argc, char **argv)
{
    static uint8_t buf[MAX_DATAGRAM];
    size_t n;
    if (argc != 1 || frame_text_parse_hex(argv[0], buf, sizeof buf, &n) != 0) {
        return EXIT_USAGE;
    }
    arm_can_frame_t f;
    double ts = 0.0;
    const int rc = arm_pycan_decode(buf, n, &f, &ts);
    if (rc != ARM_PYCAN_OK) {
        printf("error %s\n", arm_pycan_errname(rc));
        return EXIT_CODEC;
    }
    frame_text_print(stdout, &f);
    printf(" %.17g\n", ts);
    return 0;
}

static int dispatch(int argc, char **argv)
{
    if (argc >= 1 && strcmp(argv[0], "encode") == 0) {
        return do_encode(argc - 1, argv + 1);
    }
    if (argc >= 1 && strcmp(argv[0], "decode") == 0) {
        return do_decode(argc - 1, argv + 1);
    }
    return EXIT_USAGE;
}

/* Python feeds thousands of cases; one process for all of them keeps the test fast. */
static int do_batch(void)
{
    static char line[2u * MAX_DATAGRAM + 64u];
    while (fgets(line, (int)sizeof line, stdin) != NULL) {
        char *argv[8];
        int argc = 0;
        for (char *tok = strtok(line, " \t\r\n"); tok != NULL && argc < 8;
             tok = strtok(NULL, " \t\r\n")) {
            argv[argc++] = tok;
        }
        if (dispatch(argc, argv) == EXIT_USAGE) {
            printf("error usage\n");
        }
        fflush(stdout);
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc == 2 && strcmp(argv[1], "batch") == 0) {
        return do_batch();
    }
    const int rc = dispatch(argc - 1, argv + 1);
    if (rc == EXIT_USAGE) {
        fprintf(stderr,
                "usage: %s encode ID LEN HEXDATA FLAGS [TIMESTAMP] | decode HEX | batch\n",
                argv[0]);
    }
    return rc;
}
