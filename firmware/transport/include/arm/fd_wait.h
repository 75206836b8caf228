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

/* A socket transport's one non-blocking read attempt: ARM_FD_READ_FRAME with a frame,
 * ARM_FD_READ_NONE when nothing is queued, ARM_FD_READ_SKIPPED for a frame it could not decode
 * (counted by it), or its own error code (< 0, counted by it). */
typedef int (*arm_fd_try_read_t)(void *ctx);
enum { ARM_FD_READ_NONE = 0, ARM_FD_READ_FRAME = 1, ARM_FD_READ_SKIPPED = 2 };
#define ARM_FD_E_IO (-1) /* what arm_fd_recv returns when the socket fails; each transport's E_IO */

/* The receive loop of the socket transports: try_read first (queued frames are served without a
 * poll syscall, even at timeout_us 0), then waits on fd until timeout_us from now (< 0: no limit)
 * between attempts. Returns 1 with a frame, 0 at the deadline or after max_skip skipped frames,
 * try_read's error as is, or ARM_FD_E_IO with *rx_errors counted when the wait fails or, with
 * error_without_data, when fd reports an error or hang-up and nothing to read (errno from
 * SO_ERROR, else EIO) instead of spinning until the deadline. */
int arm_fd_recv(int fd, int timeout_us, int max_skip, int error_without_data, uint64_t *rx_errors,
                arm_fd_try_read_t try_read, void *ctx);

#endif
