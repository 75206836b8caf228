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
#include <linux/filter.h>
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


static int fail(arm_can_udp_t *bus, char *err, size_t errcap, const char *step)
{
    const int e = errno;
    if (err != NULL && errcap > 0u) {
        snprintf(err, errcap, "can_udp open: %s: %s", step, e != 0 ? strerror(e) : "failed");
    }
    arm_can_udp_close(bus);
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
    bus->tx_fd = -1;
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

    /* The sending socket: its own ephemeral port on 127.0.0.1, the same confinement. */
    bus->tx_fd = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (bus->tx_fd < 0) {
        return fail(bus, err, errcap, "socket(AF_INET, SOCK_DGRAM) for sending");
    }
    if (set_int(bus->tx_fd, IPPROTO_IP, IP_MULTICAST_TTL, 0) != 0 ||
        setsockopt(bus->tx_fd, IPPROTO_IP, IP_MULTICAST_IF, &lo, (socklen_t)sizeof lo) != 0 ||
        set_int(bus->tx_fd, IPPROTO_IP, IP_MULTICAST_LOOP, 1) != 0) {
        return fail(bus, err, errcap, "setsockopt(IP_MULTICAST_TTL=0, IF=127.0.0.1, LOOP=1) for sending");
    }
    if (verify_loopback_only(bus->tx_fd) != 0) {
        return fail(bus, err, errcap, "verify that the sending socket's multicast TTL is zero and its "
                    "interface is loopback");
    }
    struct sockaddr_in local;
    memset(&local, 0, sizeof local);
    local.sin_family = AF_INET;
    local.sin_addr = lo;
    socklen_t llen = (socklen_t)sizeof local;
    if (bind(bus->tx_fd, (const struct sockaddr *)&local, (socklen_t)sizeof local) != 0 ||
        getsockname(bus->tx_fd, (struct sockaddr *)&local, &llen) != 0) {
        return fail(bus, err, errcap, "bind(127.0.0.1:0) for sending");
    }
    bus->tx_port = ntohs(local.sin_port);
    /* Our own datagrams come back through the loop: drop them in the kernel, before they are
     * queued (a UDP socket filter sees the UDP header at offset 0: the source port first). */
    struct sock_filter code[] = {
        BPF_STMT(BPF_LD | BPF_H | BPF_ABS, 0),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, bus->tx_port, 0, 1),
        BPF_STMT(BPF_RET | BPF_K, 0),
        BPF_STMT(BPF_RET | BPF_K, 0xFFFFFFFFu),
    };
    const struct sock_fprog prog = {.len = (unsigned short)(sizeof code / sizeof code[0]), .filter = code};
    if (setsockopt(bus->fd, SOL_SOCKET, SO_ATTACH_FILTER, &prog, (socklen_t)sizeof prog) != 0) {
        return fail(bus, err, errcap, "setsockopt(SO_ATTACH_FILTER): own-echo filter");
    }

    /* The kernel's count of datagrams dropped on our full receive queue, as ancillary data. */
    const int one = 1;
    (void)setsockopt(bus->fd, SOL_SOCKET, SO_RXQ_OVFL, &one, (socklen_t)sizeof one);

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

static void group_addr(const arm_can_udp_t *bus, struct sockaddr_in *dst)
{
    memset(dst, 0, sizeof *dst);
    dst->sin_family = AF_INET;
    dst->sin_port = htons(bus->port);
    dst->sin_addr.s_addr = bus->group_be;
}

/* errno of a failed send -> the result code, counted. */
static int send_failed(arm_can_udp_t *bus, unsigned frames)
{
    /* A real CAN controller drops on a full mailbox too; retrying here would stall the loop. */
    if (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS || errno == EINTR) {
        bus->tx_would_block += frames;
        return ARM_CAN_UDP_E_WOULD_BLOCK;
    }
    bus->tx_errors += frames;
    return ARM_CAN_UDP_E_IO;
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
    group_addr(bus, &dst);
    bus->tx_syscalls++;
    const ssize_t sent = sendto(bus->tx_fd, buf, n, MSG_DONTWAIT | MSG_NOSIGNAL,
                                (const struct sockaddr *)&dst, (socklen_t)sizeof dst);
    if (sent < 0) {
        return send_failed(bus, 1u);
    }
    if ((size_t)sent != n) {
        bus->tx_errors++;
        errno = EMSGSIZE;
        return ARM_CAN_UDP_E_IO;
    }
    bus->tx_frames++;
    return ARM_CAN_UDP_OK;
}

unsigned arm_can_udp_send_many(arm_can_udp_t *bus, const arm_can_frame_t *frames, unsigned n,
                               double timestamp)
{
    if (bus == NULL || frames == NULL || bus->fd < 0) {
        return 0u;
    }
    if (n > ARM_CAN_UDP_TX_BATCH) {
        n = ARM_CAN_UDP_TX_BATCH;
    }
    uint8_t buf[ARM_CAN_UDP_TX_BATCH][ARM_PYCAN_MAX_ENCODED];
    struct iovec iov[ARM_CAN_UDP_TX_BATCH];
    struct mmsghdr msgs[ARM_CAN_UDP_TX_BATCH];
    struct sockaddr_in dst;
    group_addr(bus, &dst);
    memset(msgs, 0, sizeof msgs);
    unsigned k = 0; /* encodable frames, in order */
    for (unsigned i = 0; i < n; ++i) {
        const size_t len = arm_pycan_encode(&frames[i], timestamp, buf[k], sizeof buf[k]);
        if (len == 0u) {
            bus->tx_invalid++;
            continue;
        }
        iov[k].iov_base = buf[k];
        iov[k].iov_len = len;
        msgs[k].msg_hdr.msg_name = &dst;
        msgs[k].msg_hdr.msg_namelen = (socklen_t)sizeof dst;
        msgs[k].msg_hdr.msg_iov = &iov[k];
        msgs[k].msg_hdr.msg_iovlen = 1;
        ++k;
    }
    unsigned done = 0;
    while (done < k) {
        bus->tx_syscalls++;
        const int sent = sendmmsg(bus->tx_fd, msgs + done, k - done, MSG_DONTWAIT | MSG_NOSIGNAL);
        if (sent <= 0) {
            (void)send_failed(bus, k - done);
            break;
        }
        done += (unsigned)sent;
    }
    bus->tx_frames += done;
    return done;
}

/* Takes what is queued on the socket, up to a batch, into the bus's receive buffers: the count,
 * 0 when nothing is queued, <0 on an error. */
static int fill_batch(arm_can_udp_t *bus)
{
    struct mmsghdr msgs[ARM_CAN_UDP_RX_BATCH];
    struct iovec iov[ARM_CAN_UDP_RX_BATCH];
    union {
        char buf[CMSG_SPACE(sizeof(uint32_t))];
        struct cmsghdr align;
    } ctrl[ARM_CAN_UDP_RX_BATCH];
    memset(msgs, 0, sizeof msgs);
    for (unsigned i = 0; i < ARM_CAN_UDP_RX_BATCH; ++i) {
        iov[i].iov_base = bus->rx_buf[i];
        iov[i].iov_len = sizeof bus->rx_buf[i];
        msgs[i].msg_hdr.msg_iov = &iov[i];
        msgs[i].msg_hdr.msg_iovlen = 1;
        msgs[i].msg_hdr.msg_control = ctrl[i].buf;
        msgs[i].msg_hdr.msg_controllen = sizeof ctrl[i].buf;
    }
    for (;;) { /* only EINTR repeats, and a signal storm is the caller's problem */
        const int got = recvmmsg(bus->fd, msgs, ARM_CAN_UDP_RX_BATCH, MSG_DONTWAIT, NULL);
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
        for (int i = 0; i < got; ++i) {
            bus->rx_len[i] = msgs[i].msg_len;
            bus->rx_trunc[i] = (msgs[i].msg_hdr.msg_flags & MSG_TRUNC) != 0;
            for (struct cmsghdr *c = CMSG_FIRSTHDR(&msgs[i].msg_hdr); c != NULL;
                 c = CMSG_NXTHDR(&msgs[i].msg_hdr, c)) {
                if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL &&
                    c->cmsg_len >= CMSG_LEN(sizeof(uint32_t))) {
                    uint32_t drops = 0u;
                    memcpy(&drops, CMSG_DATA(c), sizeof drops);
                    /* The kernel's cumulative count also holds our own echoes, which the socket
                     * filter drops: one per datagram we sent. What is beyond them overflowed. */
                    bus->rx_kernel_drops = drops > bus->tx_frames ? drops - bus->tx_frames : 0u;
                }
            }
        }
        bus->rx_next = 0u;
        bus->rx_count = (unsigned)got;
        bus->rx_syscalls++;
        return got;
    }
}

/* One non-blocking read: 1 frame, 0 nothing queued, 2 skipped datagram, <0 error. */
static int try_read_one(arm_can_udp_t *bus, arm_can_frame_t *f, double *timestamp)
{
    if (bus->rx_next >= bus->rx_count) {
        const int got = fill_batch(bus);
        if (got <= 0) {
            return got;
        }
    }
    const unsigned i = bus->rx_next++;
    const int rc = bus->rx_trunc[i] ? ARM_PYCAN_E_TRUNCATED /* longer than python-can reads */
                                    : arm_pycan_decode(bus->rx_buf[i], bus->rx_len[i], f, timestamp);
    if (rc != ARM_PYCAN_OK) {
        bus->rx_decode_errors++;
        bus->last_decode_error = rc;
        return 2;
    }
    bus->rx_frames++;
    return 1;
}

typedef struct {
    arm_can_udp_t *bus;
    arm_can_frame_t *f;
    double *timestamp;
} read_ctx_t;

static int try_read_ctx(void *ctx)
{
    const read_ctx_t *c = ctx;
    return try_read_one(c->bus, c->f, c->timestamp);
}

_Static_assert(ARM_CAN_UDP_E_IO == ARM_FD_E_IO, "arm_fd_recv's socket error is this transport's");

int arm_can_udp_recv(arm_can_udp_t *bus, arm_can_frame_t *f, double *timestamp, int timeout_us)
{
    if (bus == NULL || f == NULL) {
        return ARM_CAN_UDP_E_INVALID;
    }
    if (bus->fd < 0) {
        return ARM_CAN_UDP_E_CLOSED;
    }
    /* An error pending on the socket is left to the next recvmmsg, which reports it. */
    read_ctx_t ctx = {bus, f, timestamp};
    return arm_fd_recv(bus->fd, timeout_us, ARM_CAN_UDP_MAX_SKIP, 0, &bus->rx_errors, try_read_ctx, &ctx);
}

void arm_can_udp_close(arm_can_udp_t *bus)
{
    if (bus == NULL) {
        return;
    }
    if (bus->fd >= 0) {
        close(bus->fd);
        bus->fd = -1;
    }
    if (bus->tx_fd >= 0) {
        close(bus->tx_fd);
        bus->tx_fd = -1;
    }
}

double arm_can_udp_now(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}
