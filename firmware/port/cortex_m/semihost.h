/* Arm semihosting (BKPT 0xAB on M-profile): console output and exit status through the debugger,
 * here QEMU's -semihosting. Only what the images need. */
#ifndef ARM_SEMIHOST_H
#define ARM_SEMIHOST_H

#include <stdint.h>

void sh_puts(const char *s);               /* SYS_WRITE0 */
void sh_put_u32(uint32_t v);                /* decimal */
void sh_put_i32(int32_t v);
void sh_put_sci(float v);                   /* d.ddde[+-]NN, no printf needed */
__attribute__((noreturn)) void sh_exit(int code); /* SYS_EXIT_EXTENDED: QEMU exits with code */
/* SYS_GET_CMDLINE: the command line the debugger passes (QEMU: -semihosting-config arg=...), the
 * arguments separated by spaces, into buf (NUL-terminated); 0, or -1 if none or it does not fit. */
int sh_get_cmdline(char *buf, uint32_t cap);

#endif
