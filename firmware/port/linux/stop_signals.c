#define _GNU_SOURCE
#include "stop_signals.h"

#include <signal.h>
#include <string.h>

void stop_signals_install(void (*handler)(int))
{
    static const int k_signals[] = {SIGTERM, SIGINT, SIGHUP};
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = handler;
    for (size_t i = 0; i < sizeof(k_signals) / sizeof(k_signals[0]); ++i) sigaction(k_signals[i], &sa, NULL);
}
