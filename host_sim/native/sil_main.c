/* arm_sil: software in the loop. The controller (firmware/port/linux: the same boot, enable,
 * supervision, control step and telemetry as arm_controller) and the emulated drives and arm (the
 * same drive state machines, frame code, bus timing, servo and uncertainty models as arm_sim) in
 * one process and one thread. Frames go through the in-process bus (mem:K, arm/can_mem.h) in the
 * order they were sent; the simulator handles its frames whenever the controller waits for an
 * answer. Telemetry is written straight into an LCM event log, so nothing is lost and no socket is
 * used. The same arguments as the two programs give the same run.json results as lockstep HIL.
 *
 *   arm_sil [--telemetry-log PATH] --controller CONTROLLER_ARGS... --simulator SIMULATOR_ARGS...
 *
 * Buses must be mem:K on both sides. Exit code: the controller's (arm_controller's codes), else the
 * simulator's (arm_sim's), else 0. */
#define _GNU_SOURCE
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/can_mem.h"
#include "arm_robot_model_data.h"
#include "controller_loop.h"
#include "lcm_sink.h"
#include "options.h"
#include "sim_canopen_loop.h"
#include "sim_loop.h"
#include "sim_options.h"
#include "sim_summary.h"
#include "summary.h"
#include "telemetry.h"
#include "stop_signals.h"

#define SIL_MAX_ARGS 512

static void on_signal(int sig)
{
    controller_stop_signal = sig; /* the controller stops at a period boundary, then the drives */
}

static void on_mujoco_warning(const char *msg)
{
    fprintf(stderr, "arm_sil: MuJoCo: %s\n", msg);
}

/* The drives' turn: whenever the controller waits for frames and none is queued. */
static void drives_turn(void *sim)
{
    (void)sim_service(sim);
}

static void canopen_drives_turn(void *sim)
{
    (void)sim_co_service(sim);
}

static int all_mem(const arm_can_bus_set_config_t *c, const char *who)
{
    for (unsigned i = 0; i < c->n; ++i) {
        if (c->parsed[i].kind != ARM_BUS_MEM) {
            fprintf(stderr, "arm_sil: %s --bus: '%s': software in the loop runs on the in-process bus (mem:K)\n", who,
                    c->spec[i]);
            return 0;
        }
    }
    return 1;
}

int main(int argc, char **argv)
{
    const char *log_path = "";
    static char *ctl_argv[SIL_MAX_ARGS], *sim_argv[SIL_MAX_ARGS];
    int ctl_argc = 0, sim_argc = 0;
    char **into = NULL;
    int *count = NULL;
    for (int i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--controller") == 0 || strcmp(argv[i], "--simulator") == 0) {
            const int ctl = argv[i][2] == 'c';
            into = ctl ? ctl_argv : sim_argv;
            count = ctl ? &ctl_argc : &sim_argc;
            into[(*count)++] = ctl ? "arm_sil --controller" : "arm_sil --simulator";
        } else if (into == NULL && strcmp(argv[i], "--telemetry-log") == 0 && i + 1 < argc) {
            log_path = argv[++i];
        } else if (into == NULL || *count >= SIL_MAX_ARGS - 1) {
            fprintf(stderr, "arm_sil: '%s': usage: arm_sil [--telemetry-log PATH] --controller ARGS... "
                    "--simulator ARGS... (at most %d arguments each)\n", argv[i], SIL_MAX_ARGS - 2);
            return 2;
        } else {
            into[(*count)++] = argv[i];
        }
    }
    if (ctl_argc == 0 || sim_argc == 0) {
        fprintf(stderr, "arm_sil: both --controller and --simulator are needed\n");
        return 2;
    }

    static options_t opt;
    static sim_options_t so;
    char err[1024];
    if (options_parse(ctl_argc, ctl_argv, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: controller: %s\n", err);
        return 2;
    }
    if (opt.mode != MODE_LOCKSTEP) {
        fprintf(stderr, "arm_sil: controller --mode: software in the loop has no wall clock: lockstep only\n");
        return 2;
    }
    opt.spin_us = 0.0; /* nothing to poll for: the drives answer within the call */
    if (sim_options_parse(sim_argc, sim_argv, &so, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: simulator: %s\n", err);
        return 2;
    }
    so.cfg.spin_us = 0.0;
    if (!all_mem(&opt.buses, "controller") || !all_mem(&so.cfg.buses, "simulator")) {
        return 2;
    }
    const int canopen = so.protocol == SIM_PROTOCOL_CANOPEN;
    if (canopen != (opt.protocol_canopen != 0)) {
        fprintf(stderr, "arm_sil: --protocol: the controller speaks %s, the simulator's drives %s: give both the same\n",
                opt.protocol_canopen ? "canopen" : "arm", canopen ? "canopen" : "arm");
        return 2;
    }
    mju_user_warning = on_mujoco_warning;
    static sim_arm_t arm;
    if (sim_arm_open(&arm, so.model, so.plant, so.keyframe, so.substeps, &so.unc, err, sizeof(err)) != 0 ||
        sim_options_finish(&so, &arm, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: simulator: %s\n", err);
        return 2;
    }

    lcm_sink_t *sink = NULL;
    if (log_path[0] != '\0' && (sink = lcm_sink_open_log(log_path, err, sizeof(err))) == NULL) {
        fprintf(stderr, "arm_sil: %s\n", err);
        sim_arm_close(&arm);
        return 1;
    }
    telemetry_t *telem = telemetry_start_inline(sink, err, sizeof(err));
    sim_telemetry_t *tel = telem != NULL ? sim_telemetry_open_sink(sink, err, sizeof(err)) : NULL;
    if (telem == NULL || tel == NULL) {
        fprintf(stderr, "arm_sil: %s\n", err);
        return 1;
    }
    telemetry_event(telem, 0, "info", "software in the loop: one process, in-process bus, telemetry to the log");
    stop_signals_install(on_signal);

    static sim_capture_t capture;
    if (sim_capture_open(&capture, so.capture, 0, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: simulator: %s\n", err);
        return 1;
    }
    so.cfg.capture = &capture;
    arm_can_mem_reset();
    arm_can_mem_set_opening_side(ARM_CAN_MEM_DRIVES);
    static sim_report_t srep;
    sim_t *sim = canopen ? NULL : sim_begin(&so.cfg, &arm, tel, &srep, err, sizeof(err));
    co_sim_t *co_sim = canopen ? sim_co_begin(&so.cfg, &so.co, &arm, tel, &srep, err, sizeof(err)) : NULL;
    if (sim == NULL && co_sim == NULL) {
        fprintf(stderr, "arm_sil: simulator: %s\n", err);
        return 1;
    }
    arm_can_mem_set_opening_side(ARM_CAN_MEM_MASTER);
    if (canopen) arm_can_mem_set_idle_hook(canopen_drives_turn, co_sim);
    else arm_can_mem_set_idle_hook(drives_turn, sim);
    static run_report_t report;
    controller_run(&opt, &ARM_ROBOT_MODEL, telem, &report);
    /* the controller's last frames: shutdown and NMT stop */
    if (canopen) (void)sim_co_service(co_sim);
    else (void)sim_service(sim);
    arm_can_mem_set_idle_hook(NULL, NULL);
    if (canopen) sim_co_end(co_sim);
    else sim_end(sim);
    telemetry_stop(telem);

    int rc = (int)report.result;
    const int sim_rc = sim_exit_code(&srep);
    if (sim_capture_close(&capture, so.capture, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: %s\n", err);
        rc = rc ? rc : 1;
    }
    if (opt.summary_path[0] != '\0' && summary_write(opt.summary_path, &opt, &report, telem, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: %s\n", err);
        rc = rc ? rc : 1;
    }
    if (so.summary[0] != '\0' && sim_write_summary(so.summary, &so, &arm, &srep, tel, 0, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sil: %s\n", err);
        rc = rc ? rc : 1;
    }
    sim_telemetry_close(tel);
    free(telem);
    if (lcm_sink_close(sink) != 0) {
        fprintf(stderr, "arm_sil: --telemetry-log %s: the log could not be written completely\n", log_path);
        rc = rc ? rc : 1;
    }
    sim_arm_close(&arm);
    if (report.result != RUN_OK) {
        fprintf(stderr, "arm_sil: controller: %s; state %s; safe stop: %s\n", report.reason,
                arm_state_str(report.final_state),
                report.stop.cause != RUN_STOP_NONE ? report.stop.safe_state : "none (never enabled)");
    }
    if (sim_rc != 0) {
        fprintf(stderr, "arm_sil: simulator: %s\n", srep.reason);
    }
    if (rc == 0 && sim_rc == 0) {
        printf("arm_sil: %u periods, %llu frames sent, %llu received, final state %s\n", report.steps_done,
               (unsigned long long)report.frames_tx, (unsigned long long)report.frames_rx,
               arm_state_str(report.final_state));
    }
    return rc != 0 ? rc : sim_rc;
}
