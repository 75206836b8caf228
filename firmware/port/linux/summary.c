#define _GNU_SOURCE
#include "summary.h"

#include "arm/pm.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

static void json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s != '\0'; ++s) {
        if (*s == '"' || *s == '\\') {
            fputc('\\', f);
            fputc(*s, f);
        } else if ((unsigned char)*s < 0x20u) {
            fprintf(f, "\\u%04x", (unsigned)(unsigned char)*s);
        } else {
            fputc(*s, f);
        }
    }
    fputc('"', f);
}

int summary_write(const char *path, const options_t *opt, const run_report_t *r,
                  const telemetry_t *telem, char *err, unsigned long errcap)
{
    char tmp[600];
    snprintf(tmp, sizeof(tmp), "%s.tmp.%ld", path, (long)getpid());
    FILE *f = fopen(tmp, "w");
    if (f == NULL) {
        snprintf(err, errcap, "--summary: cannot write '%s': %s", tmp, strerror(errno));
        return -1;
    }
    fprintf(f, "{\n  \"result\": %d,\n  \"reason\": ", (int)r->result);
    json_string(f, r->reason);
    fprintf(f, ",\n  \"method\": \"%s\",\n  \"mode\": \"%s\",\n", arm_method_str(opt->ctl.method),
            opt->mode == MODE_LOCKSTEP ? "lockstep" : "realtime");
    fprintf(f, "  \"rate_hz\": %.17g,\n  \"steps_requested\": %u,\n  \"steps_done\": %u,\n",
            opt->rate_hz, opt->steps, r->steps_done);
    fprintf(f, "  \"ref_hold_s\": %.17g,\n  \"design_hash\": \"%s\",\n", opt->ref_hold_s,
            arm_pm_design_hash());
    fprintf(f, "  \"final_state\": \"%s\",\n  \"final_fault\": \"%s\",\n",
            arm_state_str(r->final_state), arm_fault_str(r->final_fault));
    fprintf(f, "  \"wall_s\": %.6f,\n  \"boot_s\": %.6f,\n  \"overruns\": %llu,\n", r->wall_s,
            r->boot_s, (unsigned long long)r->overruns);
    fprintf(f,
            "  \"frames\": {\"tx\": %llu, \"rx\": %llu, \"tx_dropped\": %llu, \"rx_state\": %u, "
            "\"rx_heartbeat\": %u, \"rx_emcy\": %u, \"rx_own_echo\": %u, \"rx_unknown_id\": %u, "
            "\"rx_bad_length\": %u, \"rx_wrong_counter\": %u, \"rx_bad_format\": %u, "
            "\"rx_wrong_bus\": %llu},\n",
            (unsigned long long)r->frames_tx, (unsigned long long)r->frames_rx,
            (unsigned long long)r->tx_would_block, r->rx.state, r->rx.heartbeat, r->rx.emcy,
            r->rx.own_echo, r->rx.unknown_id, r->rx.bad_length, r->rx.wrong_counter,
            r->rx.bad_format, (unsigned long long)r->rx_wrong_bus);
    static const char *const names[TELEM_KIND_COUNT] = {"ARM_CTL", "ARM_TIMING", "ARM_EVENT"};
    fprintf(f, "  \"telemetry\": {\"dropped\": %llu, \"sent\": {",
            (unsigned long long)telemetry_dropped(telem));
    for (int k = 0; k < (int)TELEM_KIND_COUNT; ++k) {
        fprintf(f, "%s\"%s\": %llu", k ? ", " : "", names[k],
                (unsigned long long)telemetry_sent(telem, (telem_kind_t)k));
    }
    fprintf(f, "}, \"published\": {");
    for (int k = 0; k < (int)TELEM_KIND_COUNT; ++k) {
        fprintf(f, "%s\"%s\": %llu", k ? ", " : "", names[k],
                (unsigned long long)telemetry_published(telem, (telem_kind_t)k));
    }
    fprintf(f, "}}\n}\n");
    const int bad = ferror(f);
    if (fclose(f) != 0 || bad || rename(tmp, path) != 0) {
        snprintf(err, errcap, "--summary: cannot write '%s': %s", path, strerror(errno));
        unlink(tmp);
        return -1;
    }
    return 0;
}
