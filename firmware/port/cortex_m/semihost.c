#include "semihost.h"

#define SYS_WRITE0 0x04u
#define SYS_GET_CMDLINE 0x15u
#define SYS_EXIT 0x18u
#define SYS_EXIT_EXTENDED 0x20u
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u
#define ADP_STOPPED_RUN_TIME_ERROR 0x20023u

static uint32_t semihost(uint32_t op, const void *arg)
{
    register uint32_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

int sh_get_cmdline(char *buf, uint32_t cap)
{
    uint32_t block[2] = {(uint32_t)(uintptr_t)buf, cap};
    if (cap == 0u || semihost(SYS_GET_CMDLINE, block) != 0u || block[1] >= cap) return -1;
    buf[block[1]] = '\0';
    return 0;
}

void sh_puts(const char *s)
{
    (void)semihost(SYS_WRITE0, s);
}

void sh_put_u32(uint32_t v)
{
    char buf[12];
    int i = (int)sizeof(buf) - 1;
    buf[i] = '\0';
    do {
        buf[--i] = (char)('0' + (char)(v % 10u));
        v /= 10u;
    } while (v != 0u && i > 0);
    sh_puts(&buf[i]);
}

void sh_put_i32(int32_t v)
{
    if (v < 0) {
        sh_puts("-");
        sh_put_u32((uint32_t)(-(v + 1)) + 1u);
    } else {
        sh_put_u32((uint32_t)v);
    }
}

void sh_put_sci(float v)
{
    if (v != v) {
        sh_puts("nan");
        return;
    }
    if (v < 0.0f) {
        sh_puts("-");
        v = -v;
    }
    if (v > 3.0e38f) {
        sh_puts("inf");
        return;
    }
    int e = 0;
    if (v != 0.0f) {
        while (v >= 10.0f) { v /= 10.0f; ++e; }
        while (v < 1.0f) { v *= 10.0f; --e; }
    }
    uint32_t m = (uint32_t)(v * 100.0f + 0.5f); /* 3 significant digits */
    if (m >= 1000u) { m /= 10u; ++e; }
    char buf[16];
    buf[0] = (char)('0' + (char)(m / 100u));
    buf[1] = '.';
    buf[2] = (char)('0' + (char)((m / 10u) % 10u));
    buf[3] = (char)('0' + (char)(m % 10u));
    buf[4] = 'e';
    buf[5] = e < 0 ? '-' : '+';
    const int ae = e < 0 ? -e : e;
    buf[6] = (char)('0' + (char)(ae / 10));
    buf[7] = (char)('0' + (char)(ae % 10));
    buf[8] = '\0';
    sh_puts(buf);
}

void sh_exit(int code)
{
    const uint32_t block[2] = {ADP_STOPPED_APPLICATION_EXIT, (uint32_t)code};
    (void)semihost(SYS_EXIT_EXTENDED, block);
    /* A host without SYS_EXIT_EXTENDED: plain SYS_EXIT still tells pass from fail (0 / 1). */
    (void)semihost(SYS_EXIT, (const void *)(uintptr_t)(code == 0 ? ADP_STOPPED_APPLICATION_EXIT
                                                                : ADP_STOPPED_RUN_TIME_ERROR));
    for (;;) {
    }
}
