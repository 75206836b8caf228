/* The processor-in-the-loop image: arm_controller on the MCU. The same controller as the Linux
 * port (firmware/port/linux: options.c parses the same arguments, controller_loop.c runs the
 * CANopen master's boot, the SysTick-paced SYNC loop, the control step, the safety layer and the
 * supervision), on the MCU's clock (mcu_clock.c), CAN buses (SLCAN on the UARTs, can_uart_bus.c)
 * and telemetry (a fixed ring drained over UART4, telemetry_mcu.c).
 *
 * Its arguments come as the semihosting command line (qemu-system-arm -semihosting-config
 * enable=on,target=native,arg=--bus,arg=uart:0@1,,2,...: tools/pil_bridge builds it). Output and
 * the exit status (arm_controller's codes) go through semihosting too. */
#include <string.h>

#include "arm/can_bus.h"
#include "arm_robot_model_data.h"
#include "controller_loop.h"
#include "mcu_clock.h"
#include "options.h"
#include "semihost.h"
#include "telemetry.h"

#define CMDLINE_MAX 2048u
#define ARGS_MAX 128

uint32_t stack_high_water(void); /* startup.c */
/* telemetry_mcu.c: the run's report, after the telemetry */
void telemetry_mcu_report(telemetry_t *t, const run_report_t *r, uint32_t stack);

static int split(char *line, char **argv, int cap)
{
    int argc = 0;
    argv[argc++] = "arm_controller";
    for (char *p = strtok(line, " "); p != NULL && argc < cap; p = strtok(NULL, " ")) argv[argc++] = p;
    return argc;
}

int main(void)
{
    mcu_clock_start();
    static char line[CMDLINE_MAX];
    static char *argv[ARGS_MAX];
    int argc = 1;
    argv[0] = "arm_controller";
    if (sh_get_cmdline(line, sizeof(line)) == 0) argc = split(line, argv, ARGS_MAX);
    static options_t opt;
    static char err[512];
    const int prc = options_parse(argc, argv, &ARM_ROBOT_MODEL, &opt, err, sizeof(err));
    if (prc != 0) {
        sh_puts("arm_controller (" ARM_MCU_NAME "): ");
        sh_puts(prc == 1 ? "usage: the arguments of arm_controller, as the semihosting command line\n" : err);
        sh_puts("\n");
        return prc == 1 ? 0 : 2;
    }
    telemetry_t *telem = telemetry_start(opt.lcm_url, err, sizeof(err));
    static run_report_t report;
    controller_run(&opt, &ARM_ROBOT_MODEL, telem, &report);
    telemetry_mcu_report(telem, &report, stack_high_water());
    sh_puts("arm_controller (" ARM_MCU_NAME "): ");
    sh_puts(report.result == RUN_OK ? "ok" : report.reason);
    sh_puts("\n");
    return (int)report.result;
}
