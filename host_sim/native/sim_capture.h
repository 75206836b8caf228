/* A complete capture of the bus from the simulator's side, in candump's log format
 * (`candump -l`: "(SECONDS.MICROS) canB ID#DATA", CAN FD "ID##FDATA" with F the BRS/ESI flags), one
 * line per frame the drives received or sent on bus B. can-utils' canplayer, python-can's LogReader
 * and `cantools decode` read it. The simulator writes it in its own loop, so in lockstep nothing is
 * lost (a listener that joins the bus cannot keep up with a lockstep run). Timestamps are the
 * simulated time in lockstep (the period's start, then one microsecond a frame, so the order is
 * kept), the wall clock in realtime. */
#ifndef ARM_SIM_CAPTURE_H
#define ARM_SIM_CAPTURE_H

#include <stdint.h>
#include <stdio.h>

#include "arm/can_frame.h"

typedef struct {
    FILE *f;      /* NULL: no capture */
    double last;  /* the last timestamp written */
    int wall;     /* realtime: wall-clock timestamps */
    int failed;   /* a write failed: the capture is incomplete */
    uint64_t frames;
} sim_capture_t;

/* path "": none. -1 with err if the file cannot be created. */
int sim_capture_open(sim_capture_t *c, const char *path, int wall_clock, char *err, unsigned long errcap);
/* One frame on bus `bus` at simulated time t_sim (ignored in wall-clock mode). */
void sim_capture_frame(sim_capture_t *c, double t_sim, unsigned bus, const arm_can_frame_t *f);
/* 0, or -1 if any write failed (err names the file). */
int sim_capture_close(sim_capture_t *c, const char *path, char *err, unsigned long errcap);

#endif
