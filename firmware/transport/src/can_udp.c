/*
 * Loopback-only multicast CAN bus speaking python-can's udp_multicast format.
 *
 * The socket options are the safety case: TTL 0 + IF 127.0.0.1 keep every
 * datagram we send on this host, membership on 127.0.0.1 keeps us from
 * joining the group on a real NIC, and open() reads TTL/IF back so a kernel
 * that silently ignored them cannot leave us transmitting onto a LAN.
 */
#define _GNU_SOURCE /* ppoll, IP_MULTICAST_ALL, SOCK_NONBLOCK regardless of -std */

#include "arm/can_udp.h"

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "arm/pycan_wire.h"
#include "arm/fd_wait.h"

/* Same as python-can's GeneralPurposeUdpMulticastBus.max_buffer: what it can read, we can. */
#define RX_BUF_BYTES 4096u

static int fail(arm_can_udp_t *bus, char *err, size_t errcap, const char *step)
{
    const int e = errno;
    if (err != NULL && errcap > 0u) {
        snprintf(err, errcap, "can_udp open: %s: %s", step, e != 0 ? strerror(e) : "failed");
    }
    if (bus->fd >= 0) {
        close(bus->fd);
        bus->fd = -1;
    }
    errno = e;
    return -1;
}

static int set_int(int fd, int level, int opt, int value)
{
    return setsockopt(fd, level, opt, &value, (socklen_t)sizeof value);
}

/* Reads back what the kernel actually applied; refuses to run if it differs. */
static int verify_loopback_only(int fd)
{
    int ttl = -1;
    socklen_t len = (socklen_t)sizeof ttl;
    if (getsockopt(fd, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, &len) != 0) {
        return -1;
    }
    struct in_addr ifaddr;
    memset(&ifaddr, 0, sizeof ifaddr);
    len = (socklen_t)sizeof ifaddr;
    if (getsockopt(fd, IPPROTO_IP, IP_MULTICAST_IF, &ifaddr, &len) != 0) {
        return -1;
    }
    if (ttl != 0 || ifaddr.s_addr != htonl(INADDR_LOOPBACK)) {
        errno = EPROTO;
        return -1;
    }
    return 0;
}

int arm_can_udp_open(arm_can_udp_t *bus, const char *group, uint16_t port, char *err,
                     size_t errcap)
{
    if (err != NULL && errcap > 0u) {
        err[0] = '\0';
    }
    if (bus == NULL) {
        if (err != NULL && errcap > 0u) {
            snprintf(err, errcap, "can_udp open: bus is NULL");
        }
        return -1;
    }
    memset(bus, 0, sizeof *bus);
    bus->fd = -1;
    errno = 0;

    if (group == NULL || group[0] == '\0') {
        group = ARM_CAN_UDP_DEFAULT_GROUP;
    }
    if (port == 0u) {
        port = (uint16_t)ARM_CAN_UDP_DEFAULT_PORT;
    }
    struct in_addr grp;
    if (inet_pton(AF_INET, group, &grp) != 1 || !IN_MULTICAST(ntohl(grp.s_addr))) {
        errno = EINVAL;
        return fail(bus, err, errcap, "group is not an IPv4 multicast address");
    }
    bus->group_be = grp.s_addr;
    bus->port = port;

    bus->fd = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (bus->fd < 0) {
        return fail(bus, err, errcap, "socket(AF_INET, SOCK_DGRAM)");
    }
    /* python-can and the simulator bind the same port on this host. */
    if (set_int(bus->fd, SOL_SOCKET, SO_REUSEADDR, 1) != 0) {
        return fail(bus, err, errcap, "setsockopt(SO_REUSEADDR)");
    }
    if (set_int(bus->fd, SOL_SOCKET, SO_REUSEPORT, 1) != 0) {
        return fail(bus, err, errcap, "setsockopt(SO_REUSEPORT)");
    }
    /* Bursts from the simulator must not overflow; the kernel may cap it (rmem_max). */
    (void)set_int(bus->fd, SOL_SOCKET, SO_RCVBUF, ARM_CAN_UDP_RCVBUF_REQUEST);
    socklen_t olen = (socklen_t)sizeof bus->rcvbuf_bytes;
    if (getsockopt(bus->fd, SOL_SOCKET, SO_RCVBUF, &bus->rcvbuf_bytes, &olen) != 0) {
        bus->rcvbuf_bytes = -1;
    }

    if (set_int(bus->fd, IPPROTO_IP, IP_MULTICAST_TTL, 0) != 0) {
        return fail(bus, err, errcap, "setsockopt(IP_MULTICAST_TTL=0)");
    }
    struct in_addr lo;
    lo.s_addr = htonl(INADDR_LOOPBACK);
    if (setsockopt(bus->fd, IPPROTO_IP, IP_MULTICAST_IF, &lo, (socklen_t)sizeof lo) != 0) {
        return fail(bus, err, errcap, "setsockopt(IP_MULTICAST_IF=127.0.0.1)");
    }
    /* Peers on this host (and our own other buses) are reached only via loop. */
    if (set_int(bus->fd, IPPROTO_IP, IP_MULTICAST_LOOP, 1) != 0) {
        return fail(bus, err, errcap, "setsockopt(IP_MULTICAST_LOOP=1)");
    }
#ifdef IP_MULTICAST_ALL
    /* Otherwise Linux delivers every group any local socket joined on this port. */
    if (set_int(bus->fd, IPPROTO_IP, IP_MULTICAST_ALL, 0) != 0) {
        return fail(bus, err, errcap, "setsockopt(IP_MULTICAST_ALL=0)");
    }
#endif
    if (verify_loopback_only(bus->fd) != 0) {
        return fail(bus, err, errcap,
                    "verify that the multicast TTL is zero and the interface is loopback "
                    "(IP_MULTICAST_TTL, IP_MULTICAST_IF)");
    }

    /* Binding the group (not INADDR_ANY) keeps unicast to this port out. */
    struct sockaddr_in addr;
    memset(&addr, 0, sizeof addr);
    addr.sin_family = AF_INET;
    addr.sin_port = htons(port);
    addr.sin_addr = grp;
    if (bind(bus->fd, (const struct sockaddr *)&addr, (socklen_t)sizeof addr) != 0) {
        return fail(bus, err, errcap, "bind(group:port)");
    }
    struct ip_mreq mreq;
    memset(&mreq, 0, sizeof mreq);
    mreq.imr_multiaddr = grp;
    mreq.imr_interface = lo;
    if (setsockopt(bus->fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, (socklen_t)sizeof mreq) != 0) {
        return fail(bus, err, errcap, "setsockopt(IP_ADD_MEMBERSHIP on 127.0.0.1)");
    }
    return 0;
}

int arm_can_udp_send(arm_can_udp_t *bus, const arm_can_frame_t *f, double timestamp)
{
    if (bus == NULL || f == NULL) {
        return ARM_CAN_UDP_E_INVALID;
    }
    if (bus->fd < 0) {
        return ARM_CAN_UDP_E_CLOSED;
    }
    uint8_t buf[ARM_PYCAN_MAX_ENCODED];
    const size_t n = arm_pycan_encode(f, timestamp, buf, sizeof buf);
    if (n == 0u) {
        bus->tx_invalid++;
        return ARM_CAN_UDP_E_INVALID;
    }
    struct sockaddr_in dst;
    memset(&dst, 0, sizeof dst);
    dst.sin_family = AF_INET;
    dst.sin_port = htons(bus->port);
    dst.sin_addr.s_addr = bus->group_be;
    const ssize_t sent = sendto(bus->fd, buf, n, MSG_DONTWAIT | MSG_NOSIGNAL,
                                (const struct sockaddr *)&dst, (socklen_t)sizeof dst);
    if (sent < 0) {
        /* A real CAN controller drops on a full mailbox too; retrying here would stall the loop. */
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS || errno == EINTR) {
            bus->tx_would_block++;
            return ARM_CAN_UDP_E_WOULD_BLOCK;
        }
        bus->tx_errors++;
        return ARM_CAN_UDP_E_IO;
    }
    if ((size_t)sent != n) {
        bus->tx_errors++;
        errno = EMSGSIZE;
        return ARM_CAN_UDP_E_IO;
    }
    bus->tx_frames++;
    return ARM_CAN_UDP_OK;
}

/* One non-blocking read: 1 frame, 0 nothing queued, 2 skipped datagram, <0 error. */
static int try_read_one(arm_can_udp_t *bus, arm_can_frame_t *f, double *timestamp)
{
    uint8_t buf[RX_BUF_BYTES];
    for (;;) { /* only EINTR repeats, and a signal storm is the caller's problem */
        const ssize_t got = recv(bus->fd, buf, sizeof buf, MSG_DONTWAIT | MSG_TRUNC);
        if (got < 0) {
            if (errno == EINTR) {
                continue;
            }
            if (errno == EAGAIN || errno == EWOULDBLOCK) {
                return 0;
            }
            bus->rx_errors++;
            return ARM_CAN_UDP_E_IO;
        }
        int rc;
        if ((size_t)got > sizeof buf) {
            rc = ARM_PYCAN_E_TRUNCATED; /* MSG_TRUNC reported the real, larger size */
        } else {
            rc = arm_pycan_decode(buf, (size_t)got, f, timestamp);
        }
        if (rc != ARM_PYCAN_OK) {
            bus->rx_decode_errors++;
            bus->last_decode_error = rc;
            return 2;
        }
        bus->rx_frames++;
        return 1;
    }
}

int arm_can_udp_recv(arm_can_udp_t *bus, arm_can_frame_t *f, double *timestamp, int timeout_us)
{
    if (bus == NULL || f == NULL) {
        return ARM_CAN_UDP_E_INVALID;
    }
    if (bus->fd < 0) {
        return ARM_CAN_UDP_E_CLOSED;
    }
    const int64_t deadline = arm_deadline_ns(timeout_us);
    int skipped = 0;
    for (;;) {
        /* Drain first: queued datagrams are served without a poll syscall, even at timeout 0. */
        const int rc = try_read_one(bus, f, timestamp);
        if (rc == 1 || rc < 0) {
            return rc;
        }
        if (rc == 2) {
            if (++skipped >= ARM_CAN_UDP_MAX_SKIP) {
                return 0;
            }
            continue;
        }
        short revents = 0;
        const int w = arm_fd_wait(bus->fd, deadline, &revents);
        if (w < 0) {
            bus->rx_errors++;
            return ARM_CAN_UDP_E_IO;
        }
        if (w == 0) {
            return 0;
        }
        /* readable (or error pending): the next try_read_one sorts it out */
    }
}

void arm_can_udp_close(arm_can_udp_t *bus)
{
    if (bus != NULL && bus->fd >= 0) {
        close(bus->fd);
        bus->fd = -1;
    }
}

double arm_can_udp_now(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}
