/*
 * CAN bus over python-can's udp_multicast wire format, confined to this host.
 *
 * Every socket is loopback-only: multicast TTL 0, outgoing interface and group
 * membership on 127.0.0.1, loopback delivery on. The simulator and any
 * python-can tool (python -m can.viewer -i udp_multicast ...) on the same host
 * can join; nothing leaves the machine. Linux/POSIX only; the portable part is
 * arm/pycan_wire.h.
 *
 * A bus receives its own transmissions (loopback membership); callers filter
 * by id. Not thread-safe: one thread per arm_can_udp_t.
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

/* Result codes of send/recv (recv also returns 1 for "frame received"). */
enum {
    ARM_CAN_UDP_OK = 0,
    ARM_CAN_UDP_E_IO = -1,          /* socket error; errno is preserved */
    ARM_CAN_UDP_E_WOULD_BLOCK = -2, /* send buffer full (EAGAIN/ENOBUFS/EINTR); frame dropped */
    ARM_CAN_UDP_E_INVALID = -3,     /* frame/timestamp cannot be encoded, or NULL argument */
    ARM_CAN_UDP_E_CLOSED = -4       /* bus not open */
};

typedef struct {
    int fd;               /* -1 when closed */
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
