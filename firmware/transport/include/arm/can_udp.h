/*
 * CAN bus over python-can's udp_multicast wire format, confined to this host.
 *
 * Every socket is loopback-only: multicast TTL 0, outgoing interface and group
 * membership on 127.0.0.1, loopback delivery on. The simulator and any
 * python-can tool (python -m can.viewer -i udp_multicast ...) on the same host
 * can join; nothing leaves the machine. Linux/POSIX only; the portable part is
 * arm/pycan_wire.h.
 *
 * A bus never returns its own transmissions, as a SocketCAN socket does not:
 * it sends from a socket of its own (an ephemeral port, no membership) and a
 * kernel socket filter on the receiving socket drops datagrams from that port,
 * so a frame with an id this node sends is always another node's (a second
 * master, or a spoofer), never an echo. Not thread-safe: one thread per
 * arm_can_udp_t.
 */
#ifndef ARM_CAN_UDP_H
#define ARM_CAN_UDP_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"

#define ARM_CAN_UDP_DEFAULT_GROUP "239.74.163.2" /* python-can DEFAULT_GROUP_IPv4 */
#define ARM_CAN_UDP_DEFAULT_PORT 43113u          /* python-can default port */
#define ARM_CAN_UDP_RCVBUF_REQUEST (4 * 1024 * 1024)

/*
 * Undecodable datagrams one recv call may discard before it gives up and
 * returns 0, so a flood of garbage cannot pin the caller past its deadline
 * even with timeout 0.
 */
#define ARM_CAN_UDP_MAX_SKIP 64

/*
 * Datagrams one receive syscall (recvmmsg) takes off the socket at most. On loopback multicast
 * every frame this bus sends comes back to it, so frames arrive in bursts: batching them costs
 * one syscall per burst instead of one per frame (the lockstep loop's budget is syscalls).
 */
#define ARM_CAN_UDP_RX_BATCH 8u
#define ARM_CAN_UDP_RX_BUF 4096u /* per datagram: python-can's own receive size */
#define ARM_CAN_UDP_TX_BATCH 16u /* frames one sendmmsg carries at most */

/* Result codes of send/recv (recv also returns 1 for "frame received"). */
enum {
    ARM_CAN_UDP_OK = 0,
    ARM_CAN_UDP_E_IO = -1,          /* socket error; errno is preserved */
    ARM_CAN_UDP_E_WOULD_BLOCK = -2, /* send buffer full (EAGAIN/ENOBUFS/EINTR); frame dropped */
    ARM_CAN_UDP_E_INVALID = -3,     /* frame/timestamp cannot be encoded, or NULL argument */
    ARM_CAN_UDP_E_CLOSED = -4       /* bus not open */
};

typedef struct {
    int fd;               /* receives: bound to group:port, member on lo; -1 when closed */
    int tx_fd;            /* sends: 127.0.0.1:tx_port, TTL 0, IF lo; -1 when closed */
    uint16_t tx_port;     /* datagrams from this source port are ours: filtered out */
    uint32_t group_be;    /* multicast group, network byte order */
    uint16_t port;        /* host byte order */
    int rcvbuf_bytes;     /* SO_RCVBUF the kernel granted (Linux reports 2x the request) */
    int last_decode_error;/* arm_pycan_err_t of the latest skipped datagram, 0 if none */
    uint64_t tx_frames;   /* datagrams handed to the kernel */
    uint64_t tx_errors;   /* send failures other than would-block */
    uint64_t tx_would_block; /* frames dropped because the socket buffer was full */
    uint64_t tx_invalid;  /* frames rejected by the encoder */
    uint64_t rx_frames;   /* valid frames returned */
    uint64_t rx_decode_errors; /* datagrams skipped: undecodable or oversized */
    uint64_t rx_errors;   /* socket/poll errors */
    uint64_t rx_kernel_drops; /* datagrams the kernel dropped on our full receive queue (SO_RXQ_OVFL,
                               * less our own echoes that the filter drops: a lower bound) */
    uint64_t rx_syscalls; /* recvmmsg calls that returned datagrams */
    uint64_t tx_syscalls; /* sendto/sendmmsg calls */
    /* Received, not yet returned: rx_len[i] bytes in rx_buf[i] for rx_next <= i < rx_count. */
    unsigned rx_next, rx_count;
    uint32_t rx_len[ARM_CAN_UDP_RX_BATCH];
    uint8_t rx_trunc[ARM_CAN_UDP_RX_BATCH];
    uint8_t rx_buf[ARM_CAN_UDP_RX_BATCH][ARM_CAN_UDP_RX_BUF];
} arm_can_udp_t;

/*
 * Open and configure the bus. group NULL or "" selects the default group,
 * port 0 the default port; group must be an IPv4 multicast literal.
 * Returns 0, or -1 with a message naming the failing step in err (if err and
 * errcap allow). On failure *bus is closed (fd -1) and nothing is leaked.
 */
int arm_can_udp_open(arm_can_udp_t *bus, const char *group, uint16_t port, char *err,
                     size_t errcap);

/*
 * Send one frame; never blocks. timestamp is seconds (use arm_can_udp_now());
 * python-can replaces it with its receive time anyway.
 * Returns ARM_CAN_UDP_OK or a negative ARM_CAN_UDP_E_* code.
 */
int arm_can_udp_send(arm_can_udp_t *bus, const arm_can_frame_t *f, double timestamp);

/*
 * Send n frames (n <= ARM_CAN_UDP_TX_BATCH) in one syscall, in order. Returns how many the kernel
 * took; the rest were dropped and counted (tx_would_block, tx_invalid or tx_errors), as send()
 * would have for each.
 */
unsigned arm_can_udp_send_many(arm_can_udp_t *bus, const arm_can_frame_t *frames, unsigned n,
                               double timestamp);

/*
 * Wait up to timeout_us (0: only what is already queued; negative: no limit)
 * for the next valid frame. Undecodable datagrams are counted and skipped.
 * *timestamp (may be NULL) receives the sender's timestamp from the datagram.
 * Returns 1 with a frame, 0 on timeout (or after ARM_CAN_UDP_MAX_SKIP skipped
 * datagrams), or a negative ARM_CAN_UDP_E_* code.
 */
int arm_can_udp_recv(arm_can_udp_t *bus, arm_can_frame_t *f, double *timestamp, int timeout_us);

/* Close the socket; counters stay readable. Safe to call twice. */
void arm_can_udp_close(arm_can_udp_t *bus);

/* CLOCK_REALTIME in seconds, the timestamp convention python-can uses. */
double arm_can_udp_now(void);

#endif
