/* Where telemetry goes: published on LCM (a HIL run: the logger records it), or written straight
 * into an LCM event log (a software-in-the-loop run: one process, no socket). The same channels,
 * types and sequence numbers either way, so the analysis reads both logs alike. */
#ifndef ARM_LCM_SINK_H
#define ARM_LCM_SINK_H

#include <stddef.h>
#include <stdint.h>

typedef struct lcm_sink lcm_sink_t;

/* Publishes on LCM at url (non-empty). NULL with err on failure. */
lcm_sink_t *lcm_sink_open_url(const char *url, char *err, size_t errcap);
/* A new event log at path (truncated). NULL with err on failure. */
lcm_sink_t *lcm_sink_open_log(const char *path, char *err, size_t errcap);
/* 0 when published or written. Not thread-safe: one thread per sink. */
int lcm_sink_publish(lcm_sink_t *s, const char *channel, const void *data, unsigned len);
/* Closes the LCM instance or flushes and closes the log; 0, or -1 if the log could not be written. */
int lcm_sink_close(lcm_sink_t *s);

#endif
