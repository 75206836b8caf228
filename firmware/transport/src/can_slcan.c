#define _GNU_SOURCE
#include "arm/can_slcan.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "arm/can_bus_config.h"
#include "arm/fd_wait.h"

#define RETRY_NS 10000000LL /* between connection attempts while the peer is not listening yet */

/* Writes what the socket takes of the transmit buffer; -1 when the connection failed. */
static int flush_tx(arm_can_slcan_t *bus)
{
    size_t done = 0;
    while (done < bus->tx_len) {
        const ssize_t n = send(bus->fd, bus->tx + done, bus->tx_len - done, MSG_DONTWAIT | MSG_NOSIGNAL);
        if (n < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN || errno == EWOULDBLOCK) break;
            bus->rx_errors++;
            return -1;
        }
        done += (size_t)n;
    }
    memmove(bus->tx, bus->tx + done, bus->tx_len - done);
    bus->tx_len -= done;
    return 0;
}

static int queue_tx(arm_can_slcan_t *bus, const char *text, size_t len)
{
    if (bus->tx_len + len > sizeof(bus->tx)) {
        return -1;
    }
    memcpy(bus->tx + bus->tx_len, text, len);
    bus->tx_len += len;
    return 0;
}

int arm_can_slcan_open(arm_can_slcan_t *bus, const char *host, uint16_t port, char *err, size_t errcap)
{
    memset(bus, 0, sizeof(*bus));
    bus->fd = -1;
    arm_slcan_rx_init(&bus->dec);
    struct sockaddr_in addr;
    memset(&addr, 0, sizeof(addr));
    addr.sin_family = AF_INET;
    addr.sin_port = htons(port);
    if (inet_pton(AF_INET, host, &addr.sin_addr) != 1) {
        snprintf(err, errcap, "slcan:%s:%u: '%s' is not an IPv4 address", host, port, host);
        return -1;
    }
    const int64_t give_up = arm_mono_ns() + (int64_t)(ARM_CAN_SLCAN_CONNECT_S * 1e9);
    for (;;) {
        const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        if (fd < 0) {
            snprintf(err, errcap, "slcan:%s:%u: socket: %s", host, port, strerror(errno));
            return -1;
        }
        if (connect(fd, (const struct sockaddr *)&addr, sizeof(addr)) == 0) {
            bus->fd = fd;
            break;
        }
        const int e = errno;
        close(fd);
        if ((e != ECONNREFUSED && e != EINTR) || arm_mono_ns() > give_up) {
            snprintf(err, errcap, "slcan:%s:%u: connect: %s%s", host, port, strerror(e),
                     e == ECONNREFUSED ? " (nothing listened there within the connect timeout)" : "");
            return -1;
        }
        const struct timespec pause = {0, RETRY_NS};
        nanosleep(&pause, NULL);
    }
    const int one = 1; /* a line is a frame: it goes now, not when a segment fills */
    (void)setsockopt(bus->fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
    (void)fcntl(bus->fd, F_SETFL, fcntl(bus->fd, F_GETFL) | O_NONBLOCK);
    if (queue_tx(bus, "O\r", 2u) != 0 || flush_tx(bus) != 0) {
        snprintf(err, errcap, "slcan:%s:%u: opening the channel ('O'): %s", host, port, strerror(errno));
        arm_can_slcan_close(bus);
        return -1;
    }
    return 0;
}

int arm_can_slcan_send(arm_can_slcan_t *bus, const arm_can_frame_t *f)
{
    if (bus->fd < 0) return ARM_BUS_E_CLOSED;
    char line[ARM_SLCAN_LINE_MAX + 1u];
    const size_t len = arm_slcan_encode(f, line);
    if (len == 0u) {
        bus->tx_invalid++;
        return ARM_BUS_E_INVALID;
    }
    if (flush_tx(bus) != 0) return ARM_BUS_E_IO;
    if (queue_tx(bus, line, len) != 0) {
        bus->tx_would_block++;
        return ARM_BUS_E_WOULD_BLOCK;
    }
    bus->tx_frames++;
    return flush_tx(bus) == 0 ? ARM_BUS_OK : ARM_BUS_E_IO;
}

/* The next frame from the bytes read, reading more (without waiting) when they end. */
static int try_read(void *ctx)
{
    void **args = ctx;
    arm_can_slcan_t *bus = args[0];
    arm_can_frame_t *f = args[1];
    if (bus->tx_len > 0u && flush_tx(bus) != 0) return ARM_FD_E_IO; /* a blocked send goes on */
    for (;;) {
        while (bus->rx_pos < bus->rx_len) {
            const uint64_t refused = arm_slcan_rx_refused(&bus->dec);
            const arm_slcan_event_t ev = arm_slcan_rx_byte(&bus->dec, bus->rx[bus->rx_pos++], f);
            if (ev == ARM_SLCAN_FRAME) {
                bus->rx_frames++;
                return ARM_FD_READ_FRAME;
            }
            if (arm_slcan_rx_refused(&bus->dec) != refused) return ARM_FD_READ_SKIPPED;
        }
        if (bus->peer_closed) return ARM_FD_E_IO;
        const ssize_t n = recv(bus->fd, bus->rx, sizeof(bus->rx), MSG_DONTWAIT);
        if (n > 0) {
            bus->rx_pos = 0u;
            bus->rx_len = (size_t)n;
            continue;
        }
        if (n == 0) { /* the peer closed the connection: the bus is gone */
            bus->peer_closed = 1;
            errno = ECONNRESET;
            return ARM_FD_E_IO;
        }
        if (errno == EINTR) continue;
        if (errno == EAGAIN || errno == EWOULDBLOCK) return ARM_FD_READ_NONE;
        bus->rx_errors++;
        return ARM_FD_E_IO;
    }
}

_Static_assert(ARM_BUS_E_IO == ARM_FD_E_IO, "arm_fd_recv's socket error is the bus's");

int arm_can_slcan_recv(arm_can_slcan_t *bus, arm_can_frame_t *f, int timeout_us)
{
    if (bus->fd < 0) return ARM_BUS_E_CLOSED;
    void *ctx[2] = {bus, f};
    return arm_fd_recv(bus->fd, timeout_us, ARM_CAN_SLCAN_MAX_SKIP, 1, &bus->rx_errors, try_read, ctx);
}

void arm_can_slcan_close(arm_can_slcan_t *bus)
{
    if (bus->fd >= 0) {
        /* the last frames (an NMT stop), then C: the adapter's channel closes, and an MCU waiting
         * for it (docs/pil.md) ends after us, so neither side closes on bytes the other has not read */
        (void)queue_tx(bus, "C\r", 2u);
        for (int i = 0; i < 100 && bus->tx_len > 0u && flush_tx(bus) == 0; ++i) {
            const struct timespec pause = {0, 1000000L};
            nanosleep(&pause, NULL);
        }
        (void)shutdown(bus->fd, SHUT_WR);
        close(bus->fd);
        bus->fd = -1;
    }
}
