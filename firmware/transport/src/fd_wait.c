#define _GNU_SOURCE
#include "arm/fd_wait.h"

#include <errno.h>
#include <poll.h>
#include <sys/socket.h>
#include <time.h>

#define NS_PER_S 1000000000LL

int64_t arm_mono_ns(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * NS_PER_S + (int64_t)ts.tv_nsec;
}

int64_t arm_deadline_ns(int timeout_us)
{
    return timeout_us >= 0 ? arm_mono_ns() + (int64_t)timeout_us * 1000 : -1;
}

int arm_fd_wait(int fd, int64_t deadline_ns, short *revents)
{
    for (;;) {
        struct timespec wait;
        struct timespec *waitp = NULL;
        if (deadline_ns >= 0) {
            const int64_t left = deadline_ns - arm_mono_ns();
            if (left <= 0) {
                return 0;
            }
            wait.tv_sec = (time_t)(left / NS_PER_S);
            wait.tv_nsec = (long)(left % NS_PER_S);
            waitp = &wait;
        }
        struct pollfd pfd = {fd, POLLIN, 0};
        const int pr = ppoll(&pfd, 1, waitp, NULL);
        if (pr < 0) {
            if (errno == EINTR) {
                continue;
            }
            return -1;
        }
        if (pr == 0) {
            return 0;
        }
        *revents = pfd.revents;
        return 1;
    }
}

int arm_fd_recv(int fd, int timeout_us, int max_skip, int error_without_data, uint64_t *rx_errors,
                arm_fd_try_read_t try_read, void *ctx)
{
    const int64_t deadline = arm_deadline_ns(timeout_us);
    int skipped = 0;
    for (;;) {
        const int rc = try_read(ctx);
        if (rc == ARM_FD_READ_FRAME || rc < 0) {
            return rc;
        }
        if (rc == ARM_FD_READ_SKIPPED) {
            if (++skipped >= max_skip) {
                return 0;
            }
            continue;
        }
        short revents = 0;
        const int w = arm_fd_wait(fd, deadline, &revents);
        if (w < 0) {
            (*rx_errors)++;
            return ARM_FD_E_IO;
        }
        if (w == 0) {
            return 0;
        }
        if (error_without_data && (revents & (POLLERR | POLLHUP | POLLNVAL)) != 0 && (revents & POLLIN) == 0) {
            int soerr = 0;
            socklen_t len = (socklen_t)sizeof soerr;
            (void)getsockopt(fd, SOL_SOCKET, SO_ERROR, &soerr, &len);
            errno = soerr != 0 ? soerr : EIO;
            (*rx_errors)++;
            return ARM_FD_E_IO;
        }
        /* readable (or an error pending that the next read reports) */
    }
}
