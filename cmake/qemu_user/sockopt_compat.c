/* Socket options qemu-user does not translate, for a cross-compiled Linux controller that is
 * tested under qemu-user (linked into cross Linux builds with -Wl,--wrap=setsockopt,getsockopt;
 * see cmake/qemu_user/compat.cmake).
 *
 * On a real Linux kernel every call passes straight through: the kernel knows IP_MULTICAST_IF
 * and IP_MULTICAST_ALL (since 2.6.31), so it never answers them with ENOPROTOOPT. qemu-user
 * (7.2 and 10.0 measured) forwards the options it knows to the host kernel and answers ENOPROTOOPT
 * for the rest. Only then, and only for these two, this file steps in:
 *
 * - getsockopt(IP_MULTICAST_IF): qemu >= 8 forwards the *set* to the host kernel but not the
 *   read-back. The value returned is the one the kernel accepted for this socket (recorded when
 *   the set succeeded). If the set itself was refused (qemu 7.2), nothing was recorded and the
 *   read-back fails as before: the transport's loopback check still refuses to run. Nothing is
 *   invented.
 * - setsockopt(IP_MULTICAST_ALL, 0): a receive-side filter (datagrams of other groups joined on
 *   the same port on this host). Not applied under qemu-user; said once on stderr. The sending
 *   side, which the multicast rule is about (TTL 0, loopback interface), is unaffected.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <netinet/in.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>

int __real_setsockopt(int fd, int level, int name, const void *val, socklen_t len);
int __real_getsockopt(int fd, int level, int name, void *val, socklen_t *len);
int __wrap_setsockopt(int fd, int level, int name, const void *val, socklen_t len);
int __wrap_getsockopt(int fd, int level, int name, void *val, socklen_t *len);

#define COMPAT_MAX_FD 1024

static struct in_addr g_mcast_if[COMPAT_MAX_FD];
static unsigned char g_mcast_if_known[COMPAT_MAX_FD];

int __wrap_setsockopt(int fd, int level, int name, const void *val, socklen_t len)
{
    const int rc = __real_setsockopt(fd, level, name, val, len);
    if (level != IPPROTO_IP || fd < 0 || fd >= COMPAT_MAX_FD) {
        return rc;
    }
    if (name == IP_MULTICAST_IF) {
        g_mcast_if_known[fd] = 0;
        if (rc == 0 && val != NULL && len >= (socklen_t)sizeof(struct in_addr)) {
            /* struct ip_mreqn starts with imr_multiaddr; struct in_addr is the interface. */
            if (len >= (socklen_t)sizeof(struct ip_mreqn)) {
                g_mcast_if[fd] = ((const struct ip_mreqn *)val)->imr_address;
            } else {
                memcpy(&g_mcast_if[fd], val, sizeof(struct in_addr));
            }
            g_mcast_if_known[fd] = 1;
        }
        return rc;
    }
    if (rc != 0 && errno == ENOPROTOOPT && name == IP_MULTICAST_ALL) {
        static int said;
        if (!said) {
            said = 1;
            fprintf(stderr, "qemu-user compat: IP_MULTICAST_ALL is not translated by this "
                            "emulator; the receive-side group filter is not applied\n");
        }
        errno = 0;
        return 0;
    }
    return rc;
}

int __wrap_getsockopt(int fd, int level, int name, void *val, socklen_t *len)
{
    const int rc = __real_getsockopt(fd, level, name, val, len);
    if (rc != 0 && errno == ENOPROTOOPT && level == IPPROTO_IP && name == IP_MULTICAST_IF &&
        fd >= 0 && fd < COMPAT_MAX_FD && g_mcast_if_known[fd] && val != NULL && len != NULL &&
        *len >= (socklen_t)sizeof(struct in_addr)) {
        memcpy(val, &g_mcast_if[fd], sizeof(struct in_addr));
        *len = (socklen_t)sizeof(struct in_addr);
        errno = 0;
        return 0;
    }
    return rc;
}
