/*
 * CAN bus over Linux SocketCAN: AF_CAN / SOCK_RAW / CAN_RAW, classic and CAN FD frames.
 *
 * The socket is non-blocking and CAN_RAW_FD_FRAMES is on, so one socket carries both frame
 * kinds (the kernel reports which by the size read: CAN_MTU 16 or CANFD_MTU 72 bytes).
 * send never blocks: a full transmit queue (EAGAIN from the socket buffer, ENOBUFS from the
 * interface queue, whose length is txqueuelen: 10 by default, set it to 1000) drops the frame,
 * counts it and returns ARM_CAN_SOCKETCAN_E_WOULD_BLOCK. recv waits in poll() up to a timeout.
 *
 * Own transmissions are not received (CAN_RAW_RECV_OWN_MSGS stays off; other sockets on this
 * host do see them through the default CAN_RAW_LOOPBACK). No receive filter: every frame on the
 * interface is delivered; error frames are not (no CAN_RAW_ERR_FILTER).
 *
 * The conversion between arm_can_frame_t and the kernel's struct can_frame / canfd_frame is
 * exposed as two pure functions (no syscalls), unit-tested on machines without SocketCAN.
 * Linux only. Not thread-safe: one owner per arm_can_socketcan_t.
 */
#ifndef ARM_CAN_SOCKETCAN_H
#define ARM_CAN_SOCKETCAN_H

#include <stddef.h>
#include <stdint.h>

#include <linux/can.h>

#include "arm/can_frame.h"

/* Undecodable frames one recv call may discard before it returns 0 (same role as in can_udp). */
#define ARM_CAN_SOCKETCAN_MAX_SKIP 64
/* SO_RCVBUF asked for; the kernel may cap it (rmem_max); not fatal. */
#define ARM_CAN_SOCKETCAN_RCVBUF_REQUEST (1024 * 1024)
/* Longest interface name, without the terminating NUL (IFNAMSIZ - 1). */
#define ARM_CAN_SOCKETCAN_IFNAME_MAX 15u

/* Result codes of send/recv (recv also returns 1 for "frame received"); same values as can_udp. */
enum {
    ARM_CAN_SOCKETCAN_OK = 0,
    ARM_CAN_SOCKETCAN_E_IO = -1,          /* socket error (e.g. ENETDOWN); errno is preserved */
    ARM_CAN_SOCKETCAN_E_WOULD_BLOCK = -2, /* EAGAIN/ENOBUFS/EINTR: queue full, frame dropped */
    ARM_CAN_SOCKETCAN_E_INVALID = -3,     /* frame not sendable (see arm_socketcan_from_frame) */
    ARM_CAN_SOCKETCAN_E_CLOSED = -4       /* bus not open */
};

/* Why a received kernel frame was rejected (last_decode_error). */
typedef enum {
    ARM_SOCKETCAN_OK = 0,
    ARM_SOCKETCAN_E_ARG = -1,        /* NULL argument */
    ARM_SOCKETCAN_E_SIZE = -2,       /* read size is neither CAN_MTU nor CANFD_MTU */
    ARM_SOCKETCAN_E_BAD_LENGTH = -3, /* classic len > 8; FD len not one of the DLC steps */
    ARM_SOCKETCAN_E_BAD_ID = -4,     /* 11-bit id above 0x7FF */
    ARM_SOCKETCAN_E_BAD_FLAGS = -5   /* RTR or error flag on an FD frame */
} arm_socketcan_err_t;

/* What the kernel reads and writes: struct can_frame is the first CAN_MTU bytes of canfd_frame. */
typedef union {
    struct can_frame cc;
    struct canfd_frame fd;
} arm_socketcan_frame_t;

typedef struct {
    int fd;                    /* -1 when closed */
    int ifindex;               /* kernel interface index */
    char ifname[ARM_CAN_SOCKETCAN_IFNAME_MAX + 1u];
    int mtu;                   /* interface MTU: 72 (CANFD_MTU) = FD capable, 16 (CAN_MTU) = classic */
    int rcvbuf_bytes;          /* SO_RCVBUF the kernel granted (Linux reports 2x the request) */
    int last_decode_error;     /* arm_socketcan_err_t of the latest skipped frame, 0 if none */
    uint64_t tx_frames;        /* frames the kernel accepted */
    uint64_t tx_errors;        /* send failures other than would-block (ENETDOWN, EINVAL, ...) */
    uint64_t tx_would_block;   /* frames dropped: EAGAIN (socket buffer) / ENOBUFS (txqueuelen) */
    uint64_t tx_invalid;       /* frames rejected before the kernel (bad id/len/flags, FD on MTU 16) */
    uint64_t rx_frames;        /* valid frames returned */
    uint64_t rx_decode_errors; /* frames read but skipped (see last_decode_error) */
    uint64_t rx_errors;        /* socket/poll errors */
    uint64_t rx_kernel_drops;  /* frames the kernel dropped on our full receive queue (SO_RXQ_OVFL) */
} arm_can_socketcan_t;

/*
 * Pure conversion, frame -> kernel: validates f (id <= 0x7FF, or <= 0x1FFFFFFF with EXT; classic
 * len 0..8; FD len one of 0..8,12,16,20,24,32,48,64; BRS/ESI only with FD; RTR only classic;
 * ERR never: error frames come from the controller hardware) and fills *out (zeroed first).
 * Returns the number of bytes to write: CAN_MTU (classic) or CANFD_MTU (FD), 0 if f is invalid.
 */
size_t arm_socketcan_from_frame(const arm_can_frame_t *f, arm_socketcan_frame_t *out);

/*
 * Pure conversion, kernel -> frame: nbytes is what read() returned (CAN_MTU or CANFD_MTU).
 * Classic RTR: len is the requested DLC, data zero. Error frames (CAN_ERR_FLAG) become
 * ARM_CAN_FLAG_ERR frames. Returns ARM_SOCKETCAN_OK or a negative arm_socketcan_err_t;
 * *f is fully written (zeroed) on every call with a non-NULL f.
 */
int arm_socketcan_to_frame(const arm_socketcan_frame_t *in, size_t nbytes, arm_can_frame_t *f);

/* Name of an arm_socketcan_err_t ("ok", "size", "bad_length", ...). */
const char *arm_socketcan_errname(int err);

/*
 * Open a CAN_RAW socket bound to ifname with FD frames on. Returns 0, or -1 with a message in
 * err naming the interface and the failing step, e.g. when the kernel has no AF_CAN
 * (EAFNOSUPPORT), the interface does not exist, is not a CAN interface, or is down.
 * On failure *bus is closed (fd -1) and nothing is leaked.
 */
int arm_can_socketcan_open(arm_can_socketcan_t *bus, const char *ifname, char *err, size_t errcap);

/* Send one frame; never blocks. Returns ARM_CAN_SOCKETCAN_OK or a negative code. */
int arm_can_socketcan_send(arm_can_socketcan_t *bus, const arm_can_frame_t *f);

/*
 * Wait up to timeout_us (0: only what is already queued; negative: no limit) for the next valid
 * frame. Returns 1 with a frame, 0 on timeout (or after ARM_CAN_SOCKETCAN_MAX_SKIP skipped
 * frames), or a negative ARM_CAN_SOCKETCAN_E_* code.
 */
int arm_can_socketcan_recv(arm_can_socketcan_t *bus, arm_can_frame_t *f, int timeout_us);

/* Close the socket; counters stay readable. Safe to call twice. */
void arm_can_socketcan_close(arm_can_socketcan_t *bus);

#endif
