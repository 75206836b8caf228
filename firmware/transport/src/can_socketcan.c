/*
 * Linux SocketCAN bus: one non-blocking CAN_RAW socket with CAN FD frames enabled.
 *
 * Open fails early and says why, naming the interface: no AF_CAN in the kernel, no such
 * interface, not a CAN interface, interface down. Send drops (and counts) instead of blocking:
 * a control period must never wait for a bus queue. Receive drains what is queued before it
 * polls, counts frames it cannot represent and the kernel's own receive-queue drops.
 */
#define _GNU_SOURCE /* ppoll, SOCK_NONBLOCK regardless of -std */

#include "arm/can_socketcan.h"
#include "arm/can_bus_config.h"
#include "arm/fd_wait.h"

#include <errno.h>
#include <net/if.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <time.h>
#include <unistd.h>

#include <linux/can/raw.h>
#include <linux/if_arp.h>


#ifndef CANFD_FDF
#define CANFD_FDF 0x04 /* linux >= 5.14 headers; older kernels ignore it */
#endif

/* ---- pure conversion ------------------------------------------------------------------------ */

static int fd_len_valid(unsigned len)
{
    return len <= 8u || len == 12u || len == 16u || len == 20u || len == 24u || len == 32u ||
           len == 48u || len == 64u;
}

size_t arm_socketcan_from_frame(const arm_can_frame_t *f, arm_socketcan_frame_t *out)
{
    if (f == NULL || out == NULL) {
        return 0u;
    }
    memset(out, 0, sizeof *out);
    const unsigned flags = f->flags;
    const int is_fd = (flags & ARM_CAN_FLAG_FD) != 0u;
    const int is_ext = (flags & ARM_CAN_FLAG_EXT) != 0u;
    const int is_rtr = (flags & ARM_CAN_FLAG_RTR) != 0u;
    const unsigned known = ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS | ARM_CAN_FLAG_EXT | ARM_CAN_FLAG_ESI |
                           ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_ERR;
    if ((flags & ~known) != 0u || (flags & ARM_CAN_FLAG_ERR) != 0u) {
        return 0u; /* unknown bits, or an error frame: only the controller hardware makes those */
    }
    if (f->id > (is_ext ? CAN_EFF_MASK : CAN_SFF_MASK)) {
        return 0u;
    }
    canid_t id = (canid_t)f->id;
    if (is_ext) {
        id |= CAN_EFF_FLAG;
    }
    if (is_fd) {
        if (is_rtr || !fd_len_valid(f->len)) {
            return 0u; /* CAN FD has no remote frames */
        }
        out->fd.can_id = id;
        out->fd.len = f->len;
        out->fd.flags = (uint8_t)(CANFD_FDF | ((flags & ARM_CAN_FLAG_BRS) != 0u ? CANFD_BRS : 0) |
                                  ((flags & ARM_CAN_FLAG_ESI) != 0u ? CANFD_ESI : 0));
        memcpy(out->fd.data, f->data, f->len);
        return CANFD_MTU;
    }
    if ((flags & (ARM_CAN_FLAG_BRS | ARM_CAN_FLAG_ESI)) != 0u || f->len > CAN_MAX_DLEN) {
        return 0u; /* BRS/ESI exist only in FD frames */
    }
    out->cc.can_id = id | (is_rtr ? CAN_RTR_FLAG : 0u);
    out->cc.len = f->len; /* for a remote frame: the requested length, no data */
    if (!is_rtr) {
        memcpy(out->cc.data, f->data, f->len);
    }
    return CAN_MTU;
}

int arm_socketcan_to_frame(const arm_socketcan_frame_t *in, size_t nbytes, arm_can_frame_t *f)
{
    if (f == NULL) {
        return ARM_SOCKETCAN_E_ARG;
    }
    memset(f, 0, sizeof *f);
    if (in == NULL) {
        return ARM_SOCKETCAN_E_ARG;
    }
    if (nbytes != CAN_MTU && nbytes != CANFD_MTU) {
        return ARM_SOCKETCAN_E_SIZE;
    }
    const canid_t raw = in->fd.can_id; /* same offset in both layouts */
    const int is_ext = (raw & CAN_EFF_FLAG) != 0u;
    const uint32_t id = (uint32_t)(raw & (is_ext ? CAN_EFF_MASK : CAN_SFF_MASK));
    if (!is_ext && (raw & CAN_EFF_MASK) > CAN_SFF_MASK) {
        return ARM_SOCKETCAN_E_BAD_ID; /* bits above 11 set without EFF: not a frame we sent */
    }
    uint8_t flags = (uint8_t)(is_ext ? ARM_CAN_FLAG_EXT : 0u);
    if (nbytes == CANFD_MTU) {
        if ((raw & (CAN_RTR_FLAG | CAN_ERR_FLAG)) != 0u) {
            return ARM_SOCKETCAN_E_BAD_FLAGS;
        }
        if (!fd_len_valid(in->fd.len)) {
            return ARM_SOCKETCAN_E_BAD_LENGTH;
        }
        flags |= ARM_CAN_FLAG_FD;
        flags |= (uint8_t)((in->fd.flags & CANFD_BRS) != 0 ? ARM_CAN_FLAG_BRS : 0u);
        flags |= (uint8_t)((in->fd.flags & CANFD_ESI) != 0 ? ARM_CAN_FLAG_ESI : 0u);
        f->id = id;
        f->len = in->fd.len;
        f->flags = flags;
        memcpy(f->data, in->fd.data, in->fd.len);
        return ARM_SOCKETCAN_OK;
    }
    if (in->cc.len > CAN_MAX_DLEN) {
        return ARM_SOCKETCAN_E_BAD_LENGTH;
    }
    const int is_rtr = (raw & CAN_RTR_FLAG) != 0u;
    flags |= (uint8_t)(is_rtr ? ARM_CAN_FLAG_RTR : 0u);
    flags |= (uint8_t)((raw & CAN_ERR_FLAG) != 0u ? ARM_CAN_FLAG_ERR : 0u);
    f->id = id;
    f->len = in->cc.len;
    f->flags = flags;
    if (!is_rtr) {
        memcpy(f->data, in->cc.data, in->cc.len);
    }
    return ARM_SOCKETCAN_OK;
}

const char *arm_socketcan_errname(int err)
{
    switch (err) {
    case ARM_SOCKETCAN_OK: return "ok";
    case ARM_SOCKETCAN_E_ARG: return "arg";
    case ARM_SOCKETCAN_E_SIZE: return "size";
    case ARM_SOCKETCAN_E_BAD_LENGTH: return "bad_length";
    case ARM_SOCKETCAN_E_BAD_ID: return "bad_id";
    case ARM_SOCKETCAN_E_BAD_FLAGS: return "bad_flags";
    default: return "unknown";
    }
}


/* ---- the socket ----------------------------------------------------------------------------- */

/* Closes the socket and writes "socketcan:IFACE: <what>[: strerror(errno)]" into err. */
__attribute__((format(printf, 5, 6))) static int fail(arm_can_socketcan_t *bus, char *err,
                                                       size_t errcap, int with_errno,
                                                       const char *fmt, ...)
{
    const int e = errno;
    if (err != NULL && errcap > 0u) {
        char what[192];
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(what, sizeof what, fmt, ap);
        va_end(ap);
        if (with_errno && e != 0) {
            snprintf(err, errcap, "socketcan:%s: %s: %s", bus->ifname, what, strerror(e));
        } else {
            snprintf(err, errcap, "socketcan:%s: %s", bus->ifname, what);
        }
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

int arm_can_socketcan_open(arm_can_socketcan_t *bus, const char *ifname, char *err, size_t errcap)
{
    if (err != NULL && errcap > 0u) {
        err[0] = '\0';
    }
    if (bus == NULL) {
        if (err != NULL && errcap > 0u) {
            snprintf(err, errcap, "socketcan open: bus is NULL");
        }
        return -1;
    }
    memset(bus, 0, sizeof *bus);
    bus->fd = -1;
    errno = 0;
    if (arm_can_bus_ifname_valid(ifname) != 0) {
        errno = EINVAL;
        if (err != NULL && errcap > 0u) {
            snprintf(err, errcap, "socketcan:%s: not a valid interface name (1..15 characters, "
                     "no '/', ':' or spaces)", ifname != NULL ? ifname : "(null)");
        }
        return -1;
    }
    snprintf(bus->ifname, sizeof bus->ifname, "%s", ifname);

    bus->fd = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
    if (bus->fd < 0) {
        if (errno == EAFNOSUPPORT) {
            return fail(bus, err, errcap, 0,
                        "this kernel has no SocketCAN (AF_CAN): use --bus udp or tools/armctl vcan run");
        }
        if (errno == EPROTONOSUPPORT) {
            return fail(bus, err, errcap, 0,
                        "this kernel has AF_CAN but no CAN_RAW protocol (modprobe can-raw)");
        }
        return fail(bus, err, errcap, 1, "socket(AF_CAN, SOCK_RAW, CAN_RAW)");
    }

    struct ifreq ifr;
    memset(&ifr, 0, sizeof ifr);
    snprintf(ifr.ifr_name, sizeof ifr.ifr_name, "%s", bus->ifname);
    if (ioctl(bus->fd, SIOCGIFINDEX, &ifr) != 0) {
        if (errno == ENODEV) {
            return fail(bus, err, errcap, 0,
                        "no such interface (create it: tools/armctl vcan up, or "
                        "ip link add dev %s type vcan && ip link set %s up)",
                        bus->ifname, bus->ifname);
        }
        return fail(bus, err, errcap, 1, "SIOCGIFINDEX");
    }
    bus->ifindex = ifr.ifr_ifindex;
    if (ioctl(bus->fd, SIOCGIFHWADDR, &ifr) != 0) {
        return fail(bus, err, errcap, 1, "SIOCGIFHWADDR");
    }
    if (ifr.ifr_hwaddr.sa_family != ARPHRD_CAN) {
        return fail(bus, err, errcap, 0, "not a CAN interface (link type %u, CAN is %u)",
                    (unsigned)ifr.ifr_hwaddr.sa_family, (unsigned)ARPHRD_CAN);
    }
    if (ioctl(bus->fd, SIOCGIFFLAGS, &ifr) != 0) {
        return fail(bus, err, errcap, 1, "SIOCGIFFLAGS");
    }
    if ((ifr.ifr_flags & IFF_UP) == 0) {
        return fail(bus, err, errcap, 0, "interface is down (ip link set %s up)", bus->ifname);
    }
    bus->mtu = ioctl(bus->fd, SIOCGIFMTU, &ifr) == 0 ? ifr.ifr_mtu : -1;

    if (set_int(bus->fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 1) != 0) {
        return fail(bus, err, errcap, 1, "setsockopt(CAN_RAW_FD_FRAMES=1)");
    }
    (void)set_int(bus->fd, SOL_SOCKET, SO_RCVBUF, ARM_CAN_SOCKETCAN_RCVBUF_REQUEST);
    socklen_t olen = (socklen_t)sizeof bus->rcvbuf_bytes;
    if (getsockopt(bus->fd, SOL_SOCKET, SO_RCVBUF, &bus->rcvbuf_bytes, &olen) != 0) {
        bus->rcvbuf_bytes = -1;
    }
    /* The kernel's count of frames dropped on our receive queue arrives as ancillary data. */
    (void)set_int(bus->fd, SOL_SOCKET, SO_RXQ_OVFL, 1);

    struct sockaddr_can addr;
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = bus->ifindex;
    if (bind(bus->fd, (const struct sockaddr *)&addr, (socklen_t)sizeof addr) != 0) {
        return fail(bus, err, errcap, 1, "bind");
    }
    return 0;
}

int arm_can_socketcan_send(arm_can_socketcan_t *bus, const arm_can_frame_t *f)
{
    if (bus == NULL || f == NULL) {
        return ARM_CAN_SOCKETCAN_E_INVALID;
    }
    if (bus->fd < 0) {
        return ARM_CAN_SOCKETCAN_E_CLOSED;
    }
    arm_socketcan_frame_t kf;
    const size_t n = arm_socketcan_from_frame(f, &kf);
    if (n == 0u || (n == CANFD_MTU && bus->mtu >= 0 && bus->mtu < (int)CANFD_MTU)) {
        bus->tx_invalid++; /* an FD frame on a classic-only interface (MTU 16) is never sendable */
        return ARM_CAN_SOCKETCAN_E_INVALID;
    }
    const ssize_t sent = send(bus->fd, &kf, n, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (sent < 0) {
        /* EAGAIN: socket send buffer full; ENOBUFS: interface queue (txqueuelen) full.
         * A real controller drops on a full mailbox too; retrying here would stall the loop. */
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS || errno == EINTR) {
            bus->tx_would_block++;
            return ARM_CAN_SOCKETCAN_E_WOULD_BLOCK;
        }
        bus->tx_errors++;
        return ARM_CAN_SOCKETCAN_E_IO;
    }
    if ((size_t)sent != n) {
        bus->tx_errors++;
        errno = EMSGSIZE;
        return ARM_CAN_SOCKETCAN_E_IO;
    }
    bus->tx_frames++;
    return ARM_CAN_SOCKETCAN_OK;
}

/* One non-blocking read: 1 frame, 0 nothing queued, 2 skipped frame, <0 error. */
static int try_read_one(arm_can_socketcan_t *bus, arm_can_frame_t *f)
{
    arm_socketcan_frame_t kf;
    union {
        char buf[CMSG_SPACE(sizeof(uint32_t))];
        struct cmsghdr align;
    } ctrl;
    for (;;) { /* only EINTR repeats */
        struct iovec iov = {&kf, sizeof kf};
        struct msghdr msg;
        memset(&msg, 0, sizeof msg);
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = ctrl.buf;
        msg.msg_controllen = sizeof ctrl.buf;
        const ssize_t got = recvmsg(bus->fd, &msg, MSG_DONTWAIT);
        if (got < 0) {
            if (errno == EINTR) {
                continue;
            }
            if (errno == EAGAIN || errno == EWOULDBLOCK) {
                return 0;
            }
            bus->rx_errors++;
            return ARM_CAN_SOCKETCAN_E_IO;
        }
        for (struct cmsghdr *c = CMSG_FIRSTHDR(&msg); c != NULL; c = CMSG_NXTHDR(&msg, c)) {
            if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL &&
                c->cmsg_len >= CMSG_LEN(sizeof(uint32_t))) {
                uint32_t drops = 0u;
                memcpy(&drops, CMSG_DATA(c), sizeof drops);
                bus->rx_kernel_drops = drops; /* cumulative count kept by the kernel */
            }
        }
        const int rc = arm_socketcan_to_frame(&kf, (size_t)got, f);
        if (rc != ARM_SOCKETCAN_OK) {
            bus->rx_decode_errors++;
            bus->last_decode_error = rc;
            return 2;
        }
        bus->rx_frames++;
        return 1;
    }
}

typedef struct {
    arm_can_socketcan_t *bus;
    arm_can_frame_t *f;
} read_ctx_t;

static int try_read_ctx(void *ctx)
{
    const read_ctx_t *c = ctx;
    return try_read_one(c->bus, c->f);
}

_Static_assert(ARM_CAN_SOCKETCAN_E_IO == ARM_FD_E_IO, "arm_fd_recv's socket error is this transport's");

int arm_can_socketcan_recv(arm_can_socketcan_t *bus, arm_can_frame_t *f, int timeout_us)
{
    if (bus == NULL || f == NULL) {
        return ARM_CAN_SOCKETCAN_E_INVALID;
    }
    if (bus->fd < 0) {
        return ARM_CAN_SOCKETCAN_E_CLOSED;
    }
    /* An interface gone down polls as an error with nothing to read: reported, not waited out. */
    read_ctx_t ctx = {bus, f};
    return arm_fd_recv(bus->fd, timeout_us, ARM_CAN_SOCKETCAN_MAX_SKIP, 1, &bus->rx_errors, try_read_ctx, &ctx);
}

void arm_can_socketcan_close(arm_can_socketcan_t *bus)
{
    if (bus != NULL && bus->fd >= 0) {
        close(bus->fd);
        bus->fd = -1;
    }
}
