/* Waiting for a socket to become readable before a deadline: the one blocking step the Linux
 * transports (UDP, SocketCAN) share. */
#ifndef ARM_FD_WAIT_H
#define ARM_FD_WAIT_H

#include <stdint.h>

/* CLOCK_MONOTONIC in nanoseconds. */
int64_t arm_mono_ns(void);

/* Deadline (arm_mono_ns() time) timeout_us from now, or -1 for no limit when timeout_us < 0. */
int64_t arm_deadline_ns(int timeout_us);

/* Waits until fd is readable or has an error pending, or until deadline_ns (-1: no limit);
 * EINTR restarts the wait. Returns 1 with *revents set, 0 at the deadline, -1 when ppoll fails
 * (errno set). */
int arm_fd_wait(int fd, int64_t deadline_ns, short *revents);

#endif
