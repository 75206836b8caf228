#include "sim_plant.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "json_file.h"

void sim_plant_truth_default(sim_plant_truth_t *t)
{
    memset(t, 0, sizeof(*t));
}

int sim_plant_apply(sim_plant_t *p, const sim_plant_truth_t *truth, sim_arm_t *arm, char *err, unsigned long errcap)
{
    memset(p, 0, sizeof(*p));
    p->truth = truth;
    p->arm = arm;
    mjModel *m = arm->model;
    const int n = arm->n;
    const struct {
        const char *name;
        int count;
    } lists[] = {{"--rotor-inertia", truth->n_rotor_inertia}, {"--joint-stiffness-scale", truth->n_stiffness_scale},
                 {"--encoder-offset", truth->n_encoder_offset}, {"--gear-factor", truth->n_gear_factor}};
    for (size_t i = 0; i < sizeof(lists) / sizeof(lists[0]); ++i) {
        if (lists[i].count != 0 && lists[i].count != n) {
            snprintf(err, errcap, "%s: %d values for the arm's %d joints", lists[i].name, lists[i].count, n);
            return -1;
        }
    }
    if (((truth->reversed_motor | truth->reversed_encoder) >> n) != 0u) {
        snprintf(err, errcap, "--reversed-motor/--reversed-encoder: a joint beyond the arm's %d", n);
        return -1;
    }
    int changed = 0;
    for (int j = 0; j < n; ++j) {
        const int dof = arm->motor_dof[j];
        if (truth->n_rotor_inertia != 0 && truth->rotor_inertia[j] != 0.0) {
            m->dof_armature[dof] += truth->rotor_inertia[j];
            changed = 1;
        }
    }
    if (truth->n_stiffness_scale != 0) {
        if (!arm->flexible) {
            snprintf(err, errcap, "--joint-stiffness-scale: the arm has no flexible joint (give --plant)");
            return -1;
        }
        for (int t = 0; t < m->ntendon; ++t) { /* each gear's spring: the tendon that wraps its rotor */
            for (int w = m->tendon_adr[t]; w < m->tendon_adr[t] + m->tendon_num[t]; ++w) {
                for (int j = 0; j < n; ++j) {
                    if (m->wrap_type[w] == mjWRAP_JOINT && arm->motor_dof[j] != j &&
                        m->wrap_objid[w] == m->dof_jntid[arm->motor_dof[j]]) {
                        m->tendon_stiffness[t] *= truth->stiffness_scale[j];
                    }
                }
            }
        }
        changed = 1;
    }
    if (changed) { /* the true arm is not the nominal one: w from the nominal model's own forward pass */
        arm->nominal_differs = 1;
        arm->w_from_true_arm = 0;
        arm->w_from_plant = 0;
        mj_setConst(m, arm->data);
    }
    return 0;
}

void sim_plant_sense(const sim_plant_t *p, int j, double *q, double *qd)
{
    const sim_plant_truth_t *t = p->truth;
    double s = t->n_gear_factor != 0 ? t->gear_factor[j] : 1.0;
    if ((t->reversed_encoder >> j) & 1u) s = -s;
    *q = s * *q + (t->n_encoder_offset != 0 ? t->encoder_offset[j] : 0.0);
    *qd = s * *qd;
}

double sim_plant_actuate(const sim_plant_t *p, int j, double tau)
{
    const sim_plant_truth_t *t = p->truth;
    const double s = t->n_gear_factor != 0 ? t->gear_factor[j] : 1.0;
    return ((t->reversed_motor >> j) & 1u) ? -s * tau : s * tau;
}

static sim_plant_session_t *current(sim_plant_t *p)
{
    return p->n_sessions > 0 ? &p->sessions[(p->n_sessions - 1) % SIM_PLANT_SESSIONS_MAX] : NULL;
}

void sim_plant_session_begin(sim_plant_t *p, uint64_t period)
{
    sim_plant_session_t *last = current(p);
    if (p->watching && last != NULL) { /* the next master came before the window was over */
        last->complete = 1;
        p->watching = 0;
    }
    p->n_sessions++;
    sim_plant_session_t *s = current(p);
    memset(s, 0, sizeof(*s));
    s->index = p->n_sessions;
    p->in_session = 1;
    p->session_start_period = period;
}

void sim_plant_session_end(sim_plant_t *p, uint64_t period, const char *how)
{
    sim_plant_session_t *s = current(p);
    if (!p->in_session || s == NULL) return;
    p->in_session = 0;
    s->periods = period - p->session_start_period;
    snprintf(s->ended, sizeof(s->ended), "%s", how);
    for (int j = 0; j < p->arm->n; ++j) p->stop_q[j] = p->arm->data->qpos[j];
    p->stop_t = (double)p->arm->step_count * p->arm->period;
    p->watching = 1;
}

int sim_plant_after_step(sim_plant_t *p)
{
    sim_plant_session_t *s = current(p);
    if (!p->watching || s == NULL) return 0;
    for (int j = 0; j < p->arm->n; ++j) {
        const double d = fabs(p->arm->data->qpos[j] - p->stop_q[j]);
        if (d > s->moved_after_stop_rad[j]) s->moved_after_stop_rad[j] = d;
    }
    s->window_s = (double)p->arm->step_count * p->arm->period - p->stop_t;
    if (s->window_s + 0.5 * p->arm->period < SIM_PLANT_SETTLE_S) return 0;
    s->complete = 1;
    p->watching = 0;
    return 1;
}

const sim_plant_session_t *sim_plant_last(const sim_plant_t *p)
{
    return p->n_sessions > 0 ? &p->sessions[(p->n_sessions - 1) % SIM_PLANT_SESSIONS_MAX] : NULL;
}

/* Bit j: joint j's holding brake holds (its drive's, sim_power_stage.h). */
static unsigned braked(const sim_plant_t *p)
{
    unsigned m = 0u;
    for (int j = 0; j < p->arm->n; ++j) {
        if (p->arm->brake_nm[j] > 0.0) m |= 1u << j;
    }
    return m;
}

int sim_plant_write(const sim_plant_t *p, const char *path, char *err, unsigned long errcap)
{
    json_file_t jf;
    if (json_file_open(&jf, path, "--sessions", err, errcap) != 0) return -1;
    FILE *f = jf.f;
    const int n = p->arm->n;
    fprintf(f, "{\n  \"settle_s\": %g,\n  \"in_session\": %s,\n  \"simulated_s\": %.6f,\n  \"idle_steps\": %llu,\n"
               "  \"idle_slips\": %llu,\n  \"brakes_closed\": %u,\n  \"q\": [",
            SIM_PLANT_SETTLE_S, p->in_session ? "true" : "false", (double)p->arm->step_count * p->arm->period,
            (unsigned long long)p->idle_steps, (unsigned long long)p->idle_slips, braked(p));
    for (int j = 0; j < n; ++j) fprintf(f, "%s%.9g", j ? ", " : "", p->arm->data->qpos[j]);
    fprintf(f, "],\n  \"sessions\": [");
    const int first = p->n_sessions > SIM_PLANT_SESSIONS_MAX ? p->n_sessions - SIM_PLANT_SESSIONS_MAX : 0;
    for (int i = first; i < p->n_sessions; ++i) {
        const sim_plant_session_t *s = &p->sessions[i % SIM_PLANT_SESSIONS_MAX];
        fprintf(f, "%s\n    {\"index\": %d, \"periods\": %llu, \"ended\": \"%s\", \"window_s\": %.6f, "
                   "\"complete\": %s, \"moved_after_stop_deg\": [",
                i > first ? "," : "", s->index, (unsigned long long)s->periods, s->ended, s->window_s,
                s->complete ? "true" : "false");
        for (int j = 0; j < n; ++j) fprintf(f, "%s%.6g", j ? ", " : "", s->moved_after_stop_rad[j] * 57.29577951308232);
        fprintf(f, "]}");
    }
    fprintf(f, "\n  ]\n}\n");
    return json_file_commit(&jf, "--sessions", err, errcap);
}

void sim_plant_describe(const sim_plant_t *p, const sim_plant_session_t *s, char *out, unsigned long cap)
{
    int worst = 0;
    for (int j = 1; j < p->arm->n; ++j) {
        if (s->moved_after_stop_rad[j] > s->moved_after_stop_rad[worst]) worst = j;
    }
    snprintf(out, cap, "session %d (%s after %llu periods): in the %.2f s after the stop no joint moved more than %.3g deg "
             "(joint %d)%s", s->index, s->ended, (unsigned long long)s->periods, s->window_s,
             s->moved_after_stop_rad[worst] * 57.29577951308232, worst + 1,
             s->window_s + 0.5 * p->arm->period < SIM_PLANT_SETTLE_S ? ": the next master came before the window's end" : "");
}
