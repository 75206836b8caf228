/* The simulator's summary file (--summary) and its exit code, shared by arm_sim and arm_sil. */
#include "sim_summary.h"

#include <stdio.h>
#include <string.h>

#include "json_file.h"

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

/* The p-th percentile of a 1-us histogram of n values (the last bin: max). */
static double hist_percentile(const uint64_t *hist, uint64_t n, double p, double max)
{
    const double want = p / 100.0 * (double)n;
    uint64_t seen = 0;
    for (unsigned b = 0; b <= SIM_COST_BINS; ++b) {
        seen += hist[b];
        if ((double)seen >= want) return b < SIM_COST_BINS ? (double)(b + 1u) : max;
    }
    return max;
}

int sim_write_summary(const char *path, const sim_options_t *o, const sim_arm_t *arm, const sim_report_t *r,
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
    fprintf(f, ",\n  \"protocol\": \"%s\"", o->protocol == SIM_PROTOCOL_CANOPEN ? "canopen" : "arm");
    /* MuJoCo's own clock: substeps x timestep per period, checked against the periods run (up to the
     * stop: the periods after it are post_stop's) */
    fprintf(f, ",\n  \"mujoco_time_s\": %.6f", r->post_stop_periods > 0u ? r->post_stop_mujoco_s : arm->data->time);
    fprintf(f, ",\n  \"n_drives\": %d,\n  \"periods\": %llu,\n  \"simulated_s\": %.6f,\n", arm->n,
            (unsigned long long)r->periods, simulated);
    fprintf(f, "  \"frames_tx\": %llu,\n  \"frames_rx\": %llu,\n  \"tx_dropped\": %llu,\n",
            (unsigned long long)r->frames_tx, (unsigned long long)r->frames_rx, (unsigned long long)r->tx_dropped);
    fprintf(f, "  \"rx_foreign_drive\": %llu,\n  \"rx_unknown_id\": %llu,\n  \"rx_bad_frame\": %llu,\n"
            "  \"rx_undecodable\": %llu,\n  \"rx_kernel_drops\": %llu,\n  \"rx_wrong_bus\": %llu,\n"
            "  \"rx_duplicate_command\": %llu,\n  \"rx_sync_out_of_sequence\": %llu,\n"
            "  \"rx_pending_dropped\": %llu,\n",
            (unsigned long long)r->rx_foreign_drive, (unsigned long long)r->rx_unknown_id,
            (unsigned long long)r->rx_bad_frame, (unsigned long long)r->rx_undecodable,
            (unsigned long long)r->rx_kernel_drops, (unsigned long long)r->rx_wrong_bus,
            (unsigned long long)r->rx_duplicate_command, (unsigned long long)r->rx_sync_out_of_sequence,
            (unsigned long long)r->rx_pending_dropped);
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
    if (r->answer_n > 0u) {
        fprintf(f, "  \"answer_timing\": {\"n\": %llu, \"read_p99_us\": %.0f, \"read_max_us\": %.0f, "
                   "\"answer_p50_us\": %.0f, \"answer_p99_us\": %.0f, \"answer_max_us\": %.0f, \"last\": [",
                (unsigned long long)r->answer_n, hist_percentile(r->read_hist, r->answer_n, 99.0, r->read_max_us),
                r->read_max_us, hist_percentile(r->answer_hist, r->answer_n, 50.0, r->answer_max_us),
                hist_percentile(r->answer_hist, r->answer_n, 99.0, r->answer_max_us), r->answer_max_us);
        const unsigned kept = r->answer_last_n < SIM_ANSWER_LAST ? r->answer_last_n : SIM_ANSWER_LAST;
        for (unsigned i = 0; i < kept; ++i) {
            const int64_t *row = r->answer_last[(r->answer_last_n - kept + i) % SIM_ANSWER_LAST];
            fprintf(f, "%s[%lld, %lld, %lld]", i ? ", " : "", (long long)row[0], (long long)row[1], (long long)row[2]);
        }
        fprintf(f, "]},\n");
    } else {
        fprintf(f, "  \"answer_timing\": null,\n");
    }
    fprintf(f, "  \"post_stop\": {\"configured_s\": %.6g, \"why\": ", o->cfg.post_stop_s);
    json_string(f, r->post_stop_why);
    fprintf(f, ", \"from_step\": %lld, \"periods\": %llu, \"simulated_s\": %.6f, \"moved_deg\": [",
            (long long)r->post_stop_from_step, (unsigned long long)r->post_stop_periods,
            (double)r->post_stop_periods * arm->period);
    for (int j = 0; j < arm->n; ++j) fprintf(f, "%s%.6g", j ? ", " : "", r->post_stop_moved_rad[j] * 57.29577951308232);
    fprintf(f, "], \"statuswords\": [");
    for (int j = 0; j < arm->n; ++j) fprintf(f, "%s%u", j ? ", " : "", (unsigned)r->post_stop_statusword[j]);
    fprintf(f, "], \"braked\": [");
    for (int j = 0; j < arm->n; ++j) fprintf(f, "%s%s", j ? ", " : "", (r->post_stop_braked_mask >> j) & 1u ? "true" : "false");
    fprintf(f, "]},\n");
    fprintf(f, "  \"memory_locked\": %s,\n  \"timestep_s\": %.9g\n}\n", locked ? "true" : "false", arm->period);
    return json_file_commit(&jf, "--summary", err, errcap);
}

int sim_exit_code(const sim_report_t *r)
{
    static const struct {
        const char *result;
        int code;
    } codes[] = {{"ok", 0}, {"bus-error", 1}, {"controller-lost", 3}, {"interrupted", 4}, {"diverged", 5}};
    for (unsigned i = 0; i < sizeof(codes) / sizeof(codes[0]); ++i) {
        if (strcmp(r->result, codes[i].result) == 0) return codes[i].code;
    }
    return 1;
}
