/* The controller's end-of-run summary as JSON, for the run's analysis. */
#ifndef ARM_SUMMARY_H
#define ARM_SUMMARY_H

#include "controller_loop.h"
#include "options.h"
#include "telemetry.h"

/* Writes path atomically (temp file + rename). Returns 0, or -1 with a message in err. */
int summary_write(const char *path, const options_t *opt, const run_report_t *r,
                  const telemetry_t *telem, char *err, unsigned long errcap);

#endif
