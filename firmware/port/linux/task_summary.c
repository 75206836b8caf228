#include "task_summary.h"

#include <math.h>

#include "json_file.h"

static void floats(FILE *f, const char *name, const float *v, int n, const char *tail)
{
    fprintf(f, "\"%s\": [", name);
    for (int i = 0; i < n; ++i) fprintf(f, "%s%.9g", i ? ", " : "", (double)v[i]);
    fprintf(f, "]%s", tail);
}

static void pulse(FILE *f, const arm_cm_pulse_t *p, const char *tail)
{
    fprintf(f, "{\"delta_nm\": %.9g, \"tau_hold_nm\": %.9g, \"q_start\": %.9g, \"duration_s\": %.9g, "
               "\"accel\": %.9g, \"moved\": %.9g, \"samples\": %u}%s",
            (double)p->delta, (double)p->tau_hold, (double)p->q_start, (double)p->duration_s, (double)p->accel,
            (double)p->moved, (unsigned)p->samples, tail);
}

void task_summary_write(FILE *f, const options_t *opt, const task_report_t *r)
{
    fprintf(f, "  \"task\": {\"name\": \"%s\", \"start_move_s\": %.9g, \"start_move_rad\": %.9g, ", task_name(opt->task),
            (double)r->start_move_s, (double)r->start_move_rad);
    floats(f, "start_pose", r->start_pose, ARM_N_JOINTS, ", ");
    floats(f, "first_point", r->first_point, ARM_N_JOINTS, ", ");
    fprintf(f, "\"task_s\": %.9g, \"ended\": %s,\n    \"tracking\": {\"periods\": %u, ", (double)r->task_s,
            r->ended ? "true" : "false", (unsigned)r->track_n);
    floats(f, "max_abs_rad", r->track_max, ARM_N_JOINTS, ", ");
    float rms[ARM_N_JOINTS];
    for (int j = 0; j < ARM_N_JOINTS; ++j) rms[j] = r->track_n > 0u ? (float)sqrt(r->track_sumsq[j] / r->track_n) : 0.0f;
    floats(f, "rms_rad", rms, ARM_N_JOINTS, "}");
    if (opt->task == TASK_STREAM) {
        fprintf(f, ",\n    \"stream\": {\"plans_taken\": %llu, \"plans_refused\": %llu, \"stale_events\": %llu, "
                   "\"last_seq\": %lld, \"last_refusal\": ",
                (unsigned long long)r->plans_taken, (unsigned long long)r->plans_refused,
                (unsigned long long)r->stale_events, (long long)r->last_seq);
        json_string(f, r->last_refusal);
        fprintf(f, "}");
    }
    if (opt->task == TASK_COMMISSION) {
        const arm_cm_config_t *c = &r->cm_config;
        fprintf(f, ",\n    \"commission\": {\"status\": \"%s\", \"why_joint\": %d, \"why_value\": %.9g, "
                   "\"step\": \"%s\", \"joint_under_test\": %d,\n",
                arm_cm_status_str(r->cm_status), r->cm_why_joint, (double)r->cm_why_value, r->cm_step,
                r->cm_joint_under_test);
        fprintf(f, "      \"config\": {\"bound_rad\": %.9g, \"trip_rad\": %.9g, \"pulse_max_s\": %.9g, \"settle_s\": %.9g, "
                   "\"sweep_rad\": %.9g, \"sweep_speed\": %.9g, \"sweep_window_rad\": %.9g, ",
                (double)c->bound_rad, (double)c->trip_rad, (double)c->pulse_max_s, (double)c->settle_s,
                (double)c->sweep_rad, (double)c->sweep_speed, (double)c->sweep_window_rad);
        floats(f, "pulse_nm", c->pulse_nm, ARM_N_JOINTS, "},\n      \"model\": {");
        floats(f, "gravity_nm", r->cm_gravity_model, ARM_N_JOINTS, ", ");
        floats(f, "gravity_slope_nm_per_rad", r->cm_gravity_slope, ARM_N_JOINTS, ", ");
        floats(f, "inertia", r->cm_inertia_model, ARM_N_JOINTS, "},\n      \"joints\": [");
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            const arm_cm_joint_t *x = &r->cm_joint[j];
            const arm_cm_sweep_t *w = &x->sweep;
            fprintf(f, "%s\n        {\"tested\": %s, \"q0\": %.9g, \"excursion\": %.9g, \"pulse_pos\": ", j ? "," : "",
                    x->tested ? "true" : "false", (double)x->q0, (double)x->excursion);
            pulse(f, &x->pulse[0], ", \"pulse_neg\": ");
            pulse(f, &x->pulse[1], ",\n         ");
            fprintf(f, "\"sweep\": {\"speed\": %.9g, \"tau_up\": %.9g, \"tau_down\": %.9g, \"q_up\": %.9g, "
                       "\"q_down\": %.9g, \"n_up\": %u, \"n_down\": %u}}",
                    (double)w->speed, (double)w->tau_up, (double)w->tau_down, (double)w->q_up, (double)w->q_down,
                    (unsigned)w->n_up, (unsigned)w->n_down);
        }
        fprintf(f, "\n      ]}");
    }
    fprintf(f, "},\n");
}
