/* arm_sim: the simulated arm and its emulated drives on the CAN bus, the per-period path of the
 * hardware-in-the-loop rig in C on MuJoCo's C API. Python (tools/hil.py, python -m host_sim)
 * configures and starts it; see host_sim/README.md.
 *
 * Exit codes: 0 the controller stopped the drives (a normal end); 1 bus or telemetry error;
 * 2 bad argument or model; 3 the controller was lost (drives faulted); 4 interrupted; 5 the
 * simulation diverged (drives faulted). */
#define _GNU_SOURCE
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "json_file.h"
#include "sim_loop.h"
#include "sim_options.h"

static void on_signal(int sig)
{
    (void)sig;
    sim_stop_requested = 1;
}

/* MuJoCo's warnings go to stderr (simulator.log), not to a MUJOCO_LOG.TXT in the current folder. */
static void on_mujoco_warning(const char *msg)
{
    fprintf(stderr, "arm_sim: MuJoCo: %s\n", msg);
}

/* The p-th percentile (0..100) of the per-period cost histogram, in us (bin upper edges). */
static double cost_percentile(const sim_report_t *r, double p)
{
    if (r->cost_n == 0u) return 0.0;
    const double want = p / 100.0 * (double)r->cost_n;
    uint64_t seen = 0;
    for (unsigned b = 0; b <= SIM_COST_BINS; ++b) {
        seen += r->cost_hist[b];
        if ((double)seen >= want) return b < SIM_COST_BINS ? (double)(b + 1u) : (double)r->cost_max_ns * 1e-3;
    }
    return (double)r->cost_max_ns * 1e-3;
}

static int write_summary(const char *path, const sim_options_t *o, const sim_arm_t *arm, const sim_report_t *r,
                         const sim_telemetry_t *tel, int locked, char *err, unsigned long errcap)
{
    json_file_t jf;
    if (json_file_open(&jf, path, "--summary", err, errcap) != 0) {
        return -1;
    }
    FILE *f = jf.f;
    const double simulated = (double)r->periods * arm->period;
    fprintf(f, "{\n  \"result\": ");
    json_string(f, r->result);
    fprintf(f, ",\n  \"reason\": ");
    json_string(f, r->reason);
    fprintf(f, ",\n  \"model\": ");
    json_string(f, o->model);
    fprintf(f, ",\n  \"model_hash\": \"%016llx\",\n  \"substeps\": %d", arm->model_hash, arm->substeps);
    /* MuJoCo's own clock: substeps x timestep per period, checked against the periods run */
    fprintf(f, ",\n  \"mujoco_time_s\": %.6f", arm->data->time);
    fprintf(f, ",\n  \"n_drives\": %d,\n  \"periods\": %llu,\n  \"simulated_s\": %.6f,\n", arm->n,
            (unsigned long long)r->periods, simulated);
    fprintf(f, "  \"frames_tx\": %llu,\n  \"frames_rx\": %llu,\n  \"tx_dropped\": %llu,\n",
            (unsigned long long)r->frames_tx, (unsigned long long)r->frames_rx, (unsigned long long)r->tx_dropped);
    fprintf(f, "  \"rx_foreign_drive\": %llu,\n  \"rx_unknown_id\": %llu,\n  \"rx_bad_frame\": %llu,\n"
            "  \"rx_undecodable\": %llu,\n  \"rx_kernel_drops\": %llu,\n  \"rx_wrong_bus\": %llu,\n"
            "  \"rx_duplicate_command\": %llu,\n",
            (unsigned long long)r->rx_foreign_drive, (unsigned long long)r->rx_unknown_id,
            (unsigned long long)r->rx_bad_frame, (unsigned long long)r->rx_undecodable,
            (unsigned long long)r->rx_kernel_drops, (unsigned long long)r->rx_wrong_bus,
            (unsigned long long)r->rx_duplicate_command);
    fprintf(f, "  \"commands_missed\": %llu,\n  \"commands_late\": %llu,\n  \"commands_missed_per_drive\": [",
            (unsigned long long)r->commands_missed, (unsigned long long)r->commands_late);
    for (int j = 0; j < arm->n; ++j) {
        fprintf(f, "%s%llu", j ? ", " : "", (unsigned long long)r->commands_missed_per_drive[j]);
    }
    fprintf(f, "],\n  \"drive_faults\": [");
    int first = 1;
    for (int j = 0; j < arm->n; ++j) {
        if ((r->drive_fault_mask & (1u << j)) != 0u) {
            fprintf(f, "%s%d", first ? "" : ", ", j + 1);
            first = 0;
        }
    }
    fprintf(f, "],\n  \"bus_timing\": [");
    if (o->cfg.timing != SIM_TIMING_OFF) {
        for (unsigned b = 0; b < r->n_buses; ++b) {
            const sim_bus_stats_t *st = &r->bus_stats[b];
            const double mean = st->periods ? st->sync_to_last_cmd_sum_s / (double)st->periods : 0.0;
            fprintf(f, "%s\n    {\"bus\": %u, \"phy\": ", b ? "," : "", b);
            json_string(f, o->cfg.timelines[b].label);
            fprintf(f, ", \"drives\": [");
            int k = 0;
            for (int j = 0; j < arm->n; ++j) {
                if (arm_can_bus_set_bus_of(&o->cfg.buses, (unsigned)j) == (int)b) {
                    fprintf(f, "%s%d", k++ ? ", " : "", j + 1);
                }
            }
            fprintf(f, "], \"periods\": %llu, \"sync_to_last_cmd_max_us\": %.3f, \"sync_to_last_cmd_mean_us\": "
                    "%.3f, \"backlog_max_us\": %.3f, \"commands_late\": %llu}",
                    (unsigned long long)st->periods, st->sync_to_last_cmd_max_s * 1e6, mean * 1e6,
                    st->backlog_max_s * 1e6, (unsigned long long)st->commands_late);
        }
    }
    fprintf(f, "],\n  \"telemetry_sent\": {\"ARM_SIM\": %llu, \"ARM_SIM_EVENT\": %llu},\n"
            "  \"telemetry_errors\": %llu,\n",
            (unsigned long long)sim_telemetry_sent_truth(tel), (unsigned long long)sim_telemetry_sent_events(tel),
            (unsigned long long)sim_telemetry_errors(tel));
    fprintf(f, "  \"wall_s\": %.6f,\n  \"boot_s\": %.6f,\n  \"run_wall_s\": %.6f,\n", r->wall_s, r->boot_s,
            r->run_wall_s);
    if (r->run_wall_s > 0.0) {
        fprintf(f, "  \"realtime_factor\": %.4f,\n", simulated / r->run_wall_s);
    } else {
        fprintf(f, "  \"realtime_factor\": null,\n");
    }
    if (r->cost_n > 0u) {
        fprintf(f, "  \"period_cost_us\": {\"n\": %llu, \"p50\": %.1f, \"p99\": %.1f, \"max\": %.1f, \"mean\": %.2f},\n",
                (unsigned long long)r->cost_n, cost_percentile(r, 50.0), cost_percentile(r, 99.0),
                (double)r->cost_max_ns * 1e-3, (double)r->cost_sum_ns * 1e-3 / (double)r->cost_n);
    } else {
        fprintf(f, "  \"period_cost_us\": null,\n");
    }
    if (o->cfg.profile && r->periods > 0u) {
        const double per = 1e-3 / (double)r->periods;
        fprintf(f, "  \"profile_us_per_period\": {\"physics\": %.3f, \"bus_tx\": %.3f, \"bus_rx\": %.3f, "
                "\"telemetry\": %.3f, \"total\": %.3f},\n",
                (double)r->prof_physics_ns * per, (double)r->prof_bus_tx_ns * per, (double)r->prof_bus_rx_ns * per,
                (double)r->prof_telemetry_ns * per, r->cost_n ? (double)r->cost_sum_ns * 1e-3 / (double)r->cost_n : 0.0);
    }
    fprintf(f, "  \"memory_locked\": %s,\n  \"timestep_s\": %.9g\n}\n", locked ? "true" : "false", arm->period);
    return json_file_commit(&jf, "--summary", err, errcap);
}

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* The limit of a period: MuJoCo alone, nothing else, on the same model. */
static int bench_mj_step(const sim_arm_t *arm, long steps)
{
    mjData *d = mj_makeData(arm->model);
    if (d == NULL) return 1;
    mj_copyData(d, arm->model, arm->data);
    const int64_t t0 = mono_ns();
    for (long i = 0; i < steps; ++i) {
        mj_step(arm->model, d);
    }
    const double ns = (double)(mono_ns() - t0) / (double)steps;
    printf("{\"mj_step_ns\": %.1f, \"steps\": %ld}\n", ns, steps);
    mj_deleteData(d);
    return 0;
}

int main(int argc, char **argv)
{
    static sim_options_t o;
    char err[1024];
    const int prc = sim_options_parse(argc, argv, &o, err, sizeof(err));
    if (prc == 1) return 0;
    if (prc != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        return 2;
    }
    mju_user_warning = on_mujoco_warning;
    static sim_arm_t arm;
    if (sim_arm_open(&arm, o.model, o.keyframe, o.substeps, &o.unc, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        return 2;
    }
    if (o.bench_mj_steps > 0) {
        const int rc = bench_mj_step(&arm, o.bench_mj_steps);
        sim_arm_close(&arm);
        return rc;
    }
    if (sim_options_finish(&o, arm.n, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        sim_arm_close(&arm);
        return 2;
    }
    sim_telemetry_t *tel = sim_telemetry_open(o.lcm_url, err, sizeof(err));
    if (tel == NULL) {
        fprintf(stderr, "arm_sim: %s\n", err);
        sim_arm_close(&arm);
        return 1;
    }
    /* No page fault in the loop once it runs (MuJoCo, the buses and LCM are set up by now): a
     * realtime run's peer must not stall on one. Not permitted (not root): runs anyway. */
    const int locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    static sim_report_t rep;
    int exit_code = 0;
    if (sim_run(&o.cfg, &arm, tel, &rep, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        snprintf(rep.result, sizeof(rep.result), "bus-error");
        snprintf(rep.reason, sizeof(rep.reason), "%.390s", err);
        exit_code = 1;
    } else if (strcmp(rep.result, "controller-lost") == 0) {
        exit_code = 3;
    } else if (strcmp(rep.result, "interrupted") == 0) {
        exit_code = 4;
    } else if (strcmp(rep.result, "diverged") == 0) {
        exit_code = 5;
    } else if (strcmp(rep.result, "ok") != 0) {
        exit_code = 1;
    }
    if (o.summary[0] != '\0' && write_summary(o.summary, &o, &arm, &rep, tel, locked, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        exit_code = exit_code ? exit_code : 1;
    }
    sim_telemetry_close(tel);
    sim_arm_close(&arm);
    if (exit_code != 0) {
        fprintf(stderr, "arm_sim: %s\n", rep.reason);
    } else {
        printf("arm_sim: %llu periods, %llu frames sent, %llu received\n", (unsigned long long)rep.periods,
               (unsigned long long)rep.frames_tx, (unsigned long long)rep.frames_rx);
    }
    return exit_code;
}
