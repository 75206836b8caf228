/* --trajectory: the knots of a trajectory the controller follows (--task trajectory), read at start-up
 * into static storage (no heap): one line per knot, "t,q1,..,qn,qd1,..,qdn" (s, rad, rad/s), t from 0
 * strictly increasing; '#' lines are comments. armctl run writes it from the user's CSV after
 * checking the whole trajectory against the arm (tools/run/trajectory.py): its knots and the
 * velocities of the spline through them. Linux only (the MCU image has no file to read). */
#ifndef ARM_TRAJ_FILE_H
#define ARM_TRAJ_FILE_H

#include <stdint.h>

#include "arm/reference.h"

#define TRAJ_FILE_MAX_KNOTS 32768u

/* Reads path into the one static trajectory; fills tr (pointing into it). A malformed file is one
 * line in err naming the file, its line and what is wrong; -1. */
int traj_file_load(const char *path, arm_traj_t *tr, char *err, unsigned long errcap);

#endif
