/* arm_pil_bridge: arm_controller, run as the MCU image in qemu-system-arm (processor in the loop,
 * docs/pil.md). To a HIL run it is the controller process: it takes arm_controller's arguments,
 * publishes the same LCM telemetry, writes the same --summary, and exits with the same codes.
 *
 *   arm_pil_bridge --machine MACHINE --image ELF --port-base P --pil-summary FILE
 *                  [--icount-shift N] [--qemu PATH] -- ARM_CONTROLLER_ARGS...
 *
 * The arguments are checked here by arm_controller's own parser (firmware/port/linux/options.c),
 * then handed to the image as its semihosting command line, where the same parser reads them.
 * Its buses are its UARTs (--bus uart:N@DRIVES): UART N becomes a TCP server on 127.0.0.1:P+N
 * that the simulator connects to (arm_sim --bus slcan:127.0.0.1:P+N@DRIVES); UART4 carries the
 * image's telemetry, on P+4, which this program reads: each record is published on LCM under the
 * image's own sequence number (a record the image had to drop is a gap in the log), and the run's
 * report, which comes last, becomes the summary. --pil-summary gets what the image measured in the
 * loop: the control step's instructions per period, its stack, its SLCAN decoders' counts. QEMU
 * runs with -icount (shift N, default 0: one instruction per virtual nanosecond) and waits for
 * every socket's peer before the image starts (server=on,wait=on): no frame is lost to a late peer. */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "arm_robot_model_data.h"
#include "json_file.h"
#include "options.h"
#include "pil_link.h"
#include "summary.h"
#include "telemetry.h"

#define TELEM_UART 4
#define CMDLINE_MAX 2048u /* pil_main.c's buffer */
#define CONNECT_S 120.0

static volatile sig_atomic_t g_stop;
static pid_t g_qemu = -1;

static void on_signal(int sig)
{
    g_stop = sig;
    if (g_qemu > 0) kill(g_qemu, SIGTERM);
}

static double mono_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int cmp_u32(const void *a, const void *b)
{
    const uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* "arg=A,arg=B": QEMU's option syntax doubles a comma inside a value. */
static int semihosting_args(int argc, char **argv, char *out, size_t cap)
{
    size_t len = (size_t)snprintf(out, cap, "enable=on,target=native");
    size_t cmdline = 0;
    for (int i = 0; i < argc; ++i) {
        cmdline += strlen(argv[i]) + 1u;
        if (strchr(argv[i], ' ') != NULL) return -1; /* the image splits its command line at spaces */
        len += (size_t)snprintf(out + len, len < cap ? cap - len : 0, ",arg=");
        for (const char *c = argv[i]; *c != '\0' && len + 2u < cap; ++c) {
            out[len++] = *c;
            if (*c == ',') out[len++] = ',';
        }
        if (len + 2u >= cap) return -1;
        out[len] = '\0';
    }
    return cmdline < CMDLINE_MAX ? 0 : -1;
}

static int connect_to(uint16_t port)
{
    const double give_up = mono_s() + CONNECT_S;
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons(port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    while (!g_stop && mono_s() < give_up) {
        const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        if (fd >= 0 && connect(fd, (const struct sockaddr *)&a, sizeof(a)) == 0) return fd;
        if (fd >= 0) close(fd);
        int status;
        if (g_qemu > 0 && waitpid(g_qemu, &status, WNOHANG) == g_qemu) {
            g_qemu = -(int)WEXITSTATUS(status) - 1;
            return -1;
        }
        const struct timespec pause = {0, 20000000L};
        nanosleep(&pause, NULL);
    }
    return -1;
}

typedef struct {
    uint32_t *v;
    size_t n, cap;
} samples_t;

static void add_sample(samples_t *s, uint32_t x)
{
    if (s->n == s->cap) {
        s->cap = s->cap ? 2u * s->cap : 4096u;
        uint32_t *grown = realloc(s->v, s->cap * sizeof(uint32_t));
        if (grown == NULL) {
            fprintf(stderr, "arm_pil_bridge: out of memory\n");
            exit(1);
        }
        s->v = grown;
    }
    s->v[s->n++] = x;
}

static int write_pil_summary(const char *path, const char *machine, const char *image, int shift, int qemu_code,
                             samples_t *steps, const pil_counts_t *c, int have_report, uint64_t link_bad,
                             char *err, size_t errcap)
{
    json_file_t jf;
    if (json_file_open(&jf, path, "--pil-summary", err, (unsigned long)errcap) != 0) return -1;
    FILE *f = jf.f;
    fprintf(f, "{\n  \"machine\": \"%s\",\n  \"image\": ", machine);
    json_string(f, image);
    fprintf(f, ",\n  \"icount_shift\": %d,\n  \"qemu_exit\": %d,\n  \"report\": %s,\n  \"link_frames_refused\": %llu,\n",
            shift, qemu_code, have_report ? "true" : "false", (unsigned long long)link_bad);
    qsort(steps->v, steps->n, sizeof(uint32_t), cmp_u32);
    if (steps->n > 0u) {
        /* the median of an even count: the mean of the middle two, as numpy's */
        const double median = steps->n % 2u ? (double)steps->v[steps->n / 2u]
                                            : 0.5 * ((double)steps->v[steps->n / 2u - 1u] + (double)steps->v[steps->n / 2u]);
        fprintf(f, "  \"step_instructions\": {\"periods\": %zu, \"min\": %u, \"median\": %.1f, \"max\": %u},\n", steps->n,
                steps->v[0], median, steps->v[steps->n - 1u]);
    } else {
        fprintf(f, "  \"step_instructions\": null,\n");
    }
    fprintf(f, "  \"instructions_per_tick\": %u,\n  \"stack_high_water_bytes\": %u,\n", c->instructions_per_tick,
            c->stack_high_water);
    fprintf(f, "  \"telemetry\": {\"sent\": {\"ARM_CTL\": %u, \"ARM_TIMING\": %u, \"ARM_EVENT\": %u}, \"dropped\": %u},\n",
            c->telemetry_sent[TELEM_CONTROLLER], c->telemetry_sent[TELEM_TIMING], c->telemetry_sent[TELEM_EVENT],
            c->telemetry_dropped);
    fprintf(f, "  \"slcan\": [");
    for (unsigned b = 0; b < c->n_buses && b < PIL_BUSES; ++b) {
        fprintf(f, "%s\n    {\"uart\": %u, \"frames\": %u, \"commands\": %u, \"garbage\": %u, \"too_long\": %u, "
                   "\"bad_dlc\": %u, \"tx_dropped\": %u, \"rx_closed\": %u}",
                b ? "," : "", b, c->slcan_frames[b], c->slcan_commands[b], c->slcan_garbage[b], c->slcan_too_long[b],
                c->slcan_bad_dlc[b], c->tx_dropped[b], c->rx_closed[b]);
    }
    fprintf(f, "\n  ]\n}\n");
    return json_file_commit(&jf, "--pil-summary", err, (unsigned long)errcap);
}

static int usage(void)
{
    fprintf(stderr, "usage: arm_pil_bridge --machine MACHINE --image ELF --port-base P --pil-summary FILE "
                    "[--icount-shift N] [--qemu PATH] -- ARM_CONTROLLER_ARGS...\n");
    return 2;
}

int main(int argc, char **argv)
{
    const char *machine = NULL, *image = NULL, *pil_path = NULL, *qemu = "qemu-system-arm";
    int port_base = 0, shift = 0, sep = -1;
    for (int i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--") == 0) {
            sep = i;
            break;
        }
        if (i + 1 >= argc) return usage();
        if (strcmp(argv[i], "--machine") == 0) machine = argv[++i];
        else if (strcmp(argv[i], "--image") == 0) image = argv[++i];
        else if (strcmp(argv[i], "--pil-summary") == 0) pil_path = argv[++i];
        else if (strcmp(argv[i], "--qemu") == 0) qemu = argv[++i];
        else if (strcmp(argv[i], "--port-base") == 0) port_base = atoi(argv[++i]);
        else if (strcmp(argv[i], "--icount-shift") == 0) shift = atoi(argv[++i]);
        else return usage();
    }
    if (sep < 0 || machine == NULL || image == NULL || pil_path == NULL || port_base < 1024 || port_base > 65530 ||
        shift < 0 || shift > 10) {
        return usage();
    }
    /* arm_controller's arguments, checked as arm_controller checks them */
    char **ctl_argv = &argv[sep];
    const int ctl_argc = argc - sep;
    ctl_argv[0] = "arm_controller";
    static options_t opt;
    char err[1024];
    const int prc = options_parse(ctl_argc, ctl_argv, &ARM_ROBOT_MODEL, &opt, err, sizeof(err));
    if (prc != 0) {
        if (prc < 0) fprintf(stderr, "arm_pil_bridge: %s\n", err);
        return prc == 1 ? 0 : 2;
    }
    int uart_used[TELEM_UART] = {0};
    for (unsigned b = 0; b < opt.buses.n; ++b) {
        if (opt.buses.parsed[b].kind != ARM_BUS_UART) {
            fprintf(stderr, "arm_pil_bridge: --bus '%s': the MCU image's buses are its UARTs (uart:0 .. uart:3)\n",
                    opt.buses.spec[b]);
            return 2;
        }
        uart_used[opt.buses.parsed[b].line] = 1;
    }
    if (opt.mode != MODE_LOCKSTEP) {
        fprintf(stderr, "arm_pil_bridge: --mode %s: the MCU image runs lockstep (its SysTick paces the SYNC; QEMU "
                        "counts instructions, not the host's time)\n", "realtime");
        return 2;
    }
    static char sh[8192];
    if (semihosting_args(ctl_argc - 1, ctl_argv + 1, sh, sizeof(sh)) != 0) {
        fprintf(stderr, "arm_pil_bridge: the arguments do not fit the image's command line (%u bytes, no spaces)\n",
                CMDLINE_MAX);
        return 2;
    }
    /* QEMU: every socket waits for its peer before the image starts */
    static char chardev[5][128], serial[5][32], icount[32];
    char *qargv[64];
    int qn = 0;
    snprintf(icount, sizeof(icount), "shift=%d", shift);
    const char *fixed[] = {qemu, "-M", machine, "-nographic", "-monitor", "none", "-icount", icount,
                           "-semihosting-config", sh, "-kernel", image};
    for (size_t i = 0; i < sizeof(fixed) / sizeof(fixed[0]); ++i) qargv[qn++] = (char *)fixed[i];
    for (int u = 0; u <= TELEM_UART; ++u) {
        if (u == TELEM_UART || uart_used[u]) {
            snprintf(chardev[u], sizeof(chardev[u]), "socket,id=u%d,host=127.0.0.1,port=%d,server=on,wait=on", u,
                     port_base + u);
            snprintf(serial[u], sizeof(serial[u]), "chardev:u%d", u);
            qargv[qn++] = "-chardev";
            qargv[qn++] = chardev[u];
        } else {
            snprintf(serial[u], sizeof(serial[u]), "null");
        }
        qargv[qn++] = "-serial";
        qargv[qn++] = serial[u];
    }
    qargv[qn] = NULL;
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    signal(SIGHUP, on_signal);
    signal(SIGPIPE, SIG_IGN);
    fflush(stdout);
    g_qemu = fork();
    if (g_qemu == 0) {
        prctl(PR_SET_PDEATHSIG, SIGKILL); /* the image goes with its bridge, however the bridge ends */
        execvp(qargv[0], qargv);
        fprintf(stderr, "arm_pil_bridge: %s: %s\n", qargv[0], strerror(errno));
        _exit(127);
    }
    if (g_qemu < 0) {
        fprintf(stderr, "arm_pil_bridge: fork: %s\n", strerror(errno));
        return 1;
    }
    telemetry_t *telem = telemetry_start(opt.lcm_url, err, sizeof(err));
    if (telem == NULL) {
        fprintf(stderr, "arm_pil_bridge: %s\n", err);
        kill(g_qemu, SIGTERM);
        waitpid(g_qemu, NULL, 0);
        return 1;
    }
    const int fd = connect_to((uint16_t)(port_base + TELEM_UART));
    static pil_decoder_t dec;
    pil_decoder_init(&dec);
    static run_report_t report;
    static pil_counts_t counts;
    samples_t steps = {0};
    int have_report = 0;
    static pil_record_t rec;
    uint8_t buf[65536];
    while (fd >= 0) {
        const ssize_t n = recv(fd, buf, sizeof(buf), 0);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        for (ssize_t i = 0; i < n; ++i) {
            if (!pil_decoder_byte(&dec, buf[i], &rec, &report, &counts)) continue;
            switch (rec.type) {
            case PIL_CTL:
                telemetry_resequence(telem, TELEM_CONTROLLER, rec.seq);
                telemetry_controller(telem, &rec.u.ctl);
                break;
            case PIL_TIMING:
                telemetry_resequence(telem, TELEM_TIMING, rec.seq);
                telemetry_timing(telem, &rec.u.t.timing);
                add_sample(&steps, rec.u.t.step_instructions);
                break;
            case PIL_EVENT:
                telemetry_resequence(telem, TELEM_EVENT, rec.seq);
                telemetry_event(telem, rec.u.event.step, rec.u.event.level, rec.u.event.text);
                break;
            case PIL_REPORT: have_report = 1; break;
            }
        }
    }
    if (fd >= 0) close(fd);
    int status = 0, qemu_code = -1;
    if (g_qemu > 0 && waitpid(g_qemu, &status, 0) == g_qemu) {
        qemu_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    } else if (g_qemu < 0) {
        qemu_code = -(int)g_qemu - 1; /* it ended before the telemetry socket opened */
    }
    if (have_report) { /* what the image sent, gaps and all: its own counts */
        for (int k = 0; k < (int)TELEM_KIND_COUNT; ++k) {
            telemetry_resequence(telem, (telem_kind_t)k, counts.telemetry_sent[k]);
        }
    }
    telemetry_stop(telem);
    int rc = qemu_code;
    if (write_pil_summary(pil_path, machine, image, shift, qemu_code, &steps, &counts, have_report, dec.bad, err,
                          sizeof(err)) != 0) {
        fprintf(stderr, "arm_pil_bridge: %s\n", err);
        rc = 1;
    }
    if (!have_report) {
        fprintf(stderr, "arm_pil_bridge: the image sent no report (QEMU exit %d%s)\n", qemu_code,
                g_stop ? ", stopped by a signal" : "");
        free(telem);
        free(steps.v);
        return g_stop ? (int)RUN_INTERRUPTED : (rc > 0 ? rc : 1);
    }
    if (opt.summary_path[0] != '\0' && summary_write(opt.summary_path, &opt, &report, telem, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_pil_bridge: %s\n", err);
        rc = 1;
    }
    free(telem);
    free(steps.v);
    return rc;
}
