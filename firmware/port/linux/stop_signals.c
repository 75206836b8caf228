#define _GNU_SOURCE
#include "stop_signals.h"

#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <unistd.h>

void stop_signals_install(void (*handler)(int))
{
    static const int k_signals[] = {SIGTERM, SIGINT, SIGHUP};
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = handler;
    for (size_t i = 0; i < sizeof(k_signals) / sizeof(k_signals[0]); ++i) sigaction(k_signals[i], &sa, NULL);
    /* The parent's death as a SIGTERM, asked for here rather than between armctl's fork and exec,
     * which would cost armctl a full fork of itself per run instead of a vfork. */
    const char *parent = getenv(ARM_PARENT_PID_ENV);
    if (parent != NULL && parent[0] != '\0') {
        (void)prctl(PR_SET_PDEATHSIG, SIGTERM, 0, 0, 0);
        if ((long)getppid() != strtol(parent, NULL, 10)) (void)raise(SIGTERM); /* it died before the prctl */
    }
}
