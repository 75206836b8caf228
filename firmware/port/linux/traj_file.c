#include "traj_file.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define COLUMNS (1 + 2 * ARM_N_JOINTS)
#define LINE_CAP 4096

static float g_t[TRAJ_FILE_MAX_KNOTS];
static float g_q[TRAJ_FILE_MAX_KNOTS * ARM_N_JOINTS];
static float g_qd[TRAJ_FILE_MAX_KNOTS * ARM_N_JOINTS];

static int fail(char *err, unsigned long errcap, const char *path, int line, const char *what)
{
    snprintf(err, errcap, "--trajectory %s:%d: %s", path, line, what);
    return -1;
}

int traj_file_load(const char *path, arm_traj_t *tr, char *err, unsigned long errcap)
{
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        snprintf(err, errcap, "--trajectory %s: %s", path, strerror(errno));
        return -1;
    }
    static char buf[LINE_CAP];
    char what[200];
    uint32_t n = 0u;
    int line = 0, rc = 0;
    while (rc == 0 && fgets(buf, sizeof(buf), f) != NULL) {
        ++line;
        const size_t len = strlen(buf);
        if (len > 0 && buf[len - 1] != '\n' && !feof(f)) {
            rc = fail(err, errcap, path, line, "line too long");
            break;
        }
        const char *p = buf + strspn(buf, " \t");
        if (*p == '#' || *p == '\n' || *p == '\r' || *p == '\0') continue;
        if (n >= TRAJ_FILE_MAX_KNOTS) {
            snprintf(what, sizeof(what), "more than %u knots", TRAJ_FILE_MAX_KNOTS);
            rc = fail(err, errcap, path, line, what);
            break;
        }
        float row[COLUMNS];
        for (int c = 0; c < COLUMNS; ++c) {
            char *end = NULL;
            errno = 0;
            const double v = strtod(p, &end);
            const char want = c + 1 < COLUMNS ? ',' : '\0';
            const char *after = end + strspn(end, " \t\r\n");
            if (end == p || errno != 0 || !isfinite(v) || (want == ',' ? *end != ',' : *after != '\0')) {
                snprintf(what, sizeof(what), "column %d: expected %d finite numbers separated by commas "
                         "(t, q1..q%d, qd1..qd%d)", c + 1, COLUMNS, ARM_N_JOINTS, ARM_N_JOINTS);
                rc = fail(err, errcap, path, line, what);
                break;
            }
            row[c] = (float)v;
            p = end + 1;
        }
        if (rc != 0) break;
        if (n == 0u ? row[0] != 0.0f : !(row[0] > g_t[n - 1u])) {
            snprintf(what, sizeof(what), "t = %g: %s", (double)row[0],
                     n == 0u ? "the first knot's time must be 0" : "times must increase strictly");
            rc = fail(err, errcap, path, line, what);
            break;
        }
        g_t[n] = row[0];
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            g_q[n * ARM_N_JOINTS + (uint32_t)j] = row[1 + j];
            g_qd[n * ARM_N_JOINTS + (uint32_t)j] = row[1 + ARM_N_JOINTS + j];
        }
        ++n;
    }
    fclose(f);
    if (rc != 0) return -1;
    if (arm_traj_init(tr, g_t, g_q, g_qd, n) != 0) {
        snprintf(err, errcap, "--trajectory %s: %u knot(s): a trajectory needs at least 2", path, n);
        return -1;
    }
    return 0;
}
