#define _GNU_SOURCE
#include "summary.h"

#include "json_file.h"
#include "task_summary.h"

#include "arm/pm.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

int summary_write(const char *path, const options_t *opt, const run_report_t *r,
                  const telemetry_t *telem, char *err, unsigned long errcap)
{
    json_file_t jf;
    if (json_file_open(&jf, path, "--summary", err, errcap) != 0) {
        return -1;
    }
    FILE *f = jf.f;
    fprintf(f, "{\n  \"result\": %d,\n  \"reason\": ", (int)r->result);
    json_string(f, r->reason);
    fprintf(f, ",\n  \"method\": \"%s\",\n  \"mode\": \"%s\",\n", arm_method_str(opt->ctl.method),
            opt->mode == MODE_LOCKSTEP ? "lockstep" : "realtime");
    fprintf(f, "  \"rate_hz\": %.17g,\n  \"steps_requested\": %u,\n  \"steps_done\": %u,\n  \"bus_periods\": %u,\n",
            opt->rate_hz, opt->steps, r->steps_done, r->bus_periods);
    fprintf(f, "  \"ref_hold_s\": %.17g,\n  \"design_hash\": \"%s\",\n", opt->ref_hold_s,
            opt->ctl.design->hash);
    fprintf(f, "  \"final_state\": \"%s\",\n  \"final_fault\": \"%s\",\n",
            arm_state_str(r->final_state), arm_fault_str(r->final_fault));
    fprintf(f, "  \"wall_s\": %.6f,\n  \"boot_s\": %.6f,\n  \"overruns\": %llu,\n", r->wall_s,
            r->boot_s, (unsigned long long)r->overruns);
    fprintf(f,
            "  \"frames\": {\"tx\": %llu, \"rx\": %llu, \"tx_dropped\": %llu, \"rx_state\": %u, "
            "\"rx_heartbeat\": %u, \"rx_emcy\": %u, \"rx_foreign_master\": %u, \"rx_unknown_id\": %u, "
            "\"rx_bad_length\": %u, \"rx_wrong_counter\": %u, \"rx_bad_format\": %u, "
            "\"rx_wrong_bus\": %llu, \"rx_undecodable\": %llu, \"rx_kernel_drops\": %llu, \"rx_sim_identity\": %u, "
            "\"rx_duplicate_state\": %u},\n",
            (unsigned long long)r->frames_tx, (unsigned long long)r->frames_rx,
            (unsigned long long)r->tx_would_block, r->rx.state, r->rx.heartbeat, r->rx.emcy,
            r->rx.foreign_master, r->rx.unknown_id, r->rx.bad_length, r->rx.wrong_counter,
            r->rx.bad_format, (unsigned long long)r->rx_wrong_bus, (unsigned long long)r->rx_undecodable,
            (unsigned long long)r->rx_kernel_drops, r->rx.sim_identity, r->rx.duplicate_state);
    static const char *const causes[] = {"none", "end of the run", "fault", "stop signal"};
    const run_stop_t *st = &r->stop;
    fprintf(f, "  \"stop\": {\"cause\": \"%s\", \"from_bus_period\": %u, \"periods\": %u, "
               "\"quick_stop_periods\": %u, \"braked\": %s, \"safe_state\": ",
            causes[(unsigned)st->cause < 4u ? st->cause : 0], st->from_bus_period, st->periods, st->quick_stop_periods,
            st->braked ? "true" : "false");
    json_string(f, st->safe_state);
    fprintf(f, ", \"statuswords\": [");
    for (unsigned j = 0; j < ARM_N_JOINTS; ++j) fprintf(f, "%s%u", j ? ", " : "", (unsigned)st->statusword[j]);
    fprintf(f, "]},\n");
    static const char *const sides[] = {"none", "plant", "controller", "bus"};
    fprintf(f, "  \"lateness\": {\"late_periods\": {\"plant\": %u, \"controller\": %u, \"bus\": %u}, "
               "\"worst_us\": {\"plant\": %d, \"controller\": %d, \"bus\": %d}, \"stop_side\": \"%s\", \"stop\": ",
            r->late_count[1], r->late_count[2], r->late_count[3], r->late_worst_us[1], r->late_worst_us[2],
            r->late_worst_us[3], sides[(unsigned)r->late_side < 4u ? r->late_side : 0]);
    json_string(f, r->late_text);
    fprintf(f, "},\n");
    fprintf(f, "  \"protocol\": \"%s\",\n", opt->protocol_canopen ? "canopen" : "arm");
    if (r->canopen) { /* the CANopen boot (arm_canopen_boot --json's sdo_writes and fault) */
        const arm_co_fault_t *cf = &r->co_fault;
        fprintf(f, "  \"canopen\": {\"boot_s\": %.6f, \"fault\": {\"code\": \"%s\", \"node\": %u, \"index\": %u, "
                   "\"sub\": %u, \"abort_code\": %u, \"value\": %u, \"tries\": %u},\n    \"sdo_writes\": [",
                r->co_boot_s, arm_co_fault_name(cf->code), cf->node, cf->index, cf->sub, cf->abort_code, cf->value,
                cf->tries);
        for (unsigned i = 0; i < r->n_co_writes; ++i) {
            const arm_co_write_t *w = &r->co_writes[i];
            fprintf(f, "%s\n      {\"node\": %u, \"index\": %u, \"sub\": %u, \"value\": %u, \"bytes\": %u}",
                    i ? "," : "", w->node, w->index, w->sub, w->value, w->len);
        }
        fprintf(f, "\n    ],\n    \"units\": [");
        for (unsigned j = 0; j < ARM_N_JOINTS; ++j) { /* each drive's, read at boot (from_table: the table's) */
            const arm_co_drive_units_t *u = &r->co_units[j];
            arm_co_units_t si; /* 1000 per-mille at the joint: 0x6076 x gear x efficiency */
            const double joint_rated =
                arm_co_units_init(&si, u->rated_torque, u->torque_units_per_nm, (double)u->gear_efficiency,
                                  u->encoder_increments, u->encoder_revs, u->gear_motor_revs, u->gear_shaft_revs,
                                  (int16_t)u->max_torque_permille) == 0 ? si.joint_rated_torque_nm : 0.0;
            fprintf(f, "%s\n      {\"rated_torque\": %u, \"torque_units_per_nm\": %u, \"encoder_increments\": %u, "
                       "\"encoder_revs\": %u, "
                       "\"gear\": [%u, %u], \"gear_efficiency\": %.9g, \"joint_rated_torque_nm\": %.9g, "
                       "\"max_torque_permille\": %u, \"modes\": %u, \"from_table\": %u}",
                    j ? "," : "", u->rated_torque, u->torque_units_per_nm, u->encoder_increments, u->encoder_revs,
                    u->gear_motor_revs,
                    u->gear_shaft_revs, (double)u->gear_efficiency, joint_rated, u->max_torque_permille, u->modes,
                    u->from_table);
        }
        fprintf(f, "\n    ],\n    \"q_first_rad\": [");
        for (unsigned j = 0; j < ARM_N_JOINTS; ++j) {
            if ((r->co_q_seen >> j) & 1u) {
                fprintf(f, "%s%.9g", j ? ", " : "", (double)r->co_q_first[j]);
            } else {
                fprintf(f, "%snull", j ? ", " : "");
            }
        }
        fprintf(f, "]},\n");
    }
    if (r->task.begun) {
        task_summary_write(f, opt, &r->task);
    }
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
    return json_file_commit(&jf, "--summary", err, errcap);
}
