/* The one argv parser (firmware/port/linux/argv_table.c) on a table of every kind, and
 * arm_controller's options through it: the registry's defaults (arm_params.h) are what a run with
 * no option gets, the core's default configuration included, and every error is one line naming
 * the option and the value. */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "argv_table.h"
#include "arm_robot_model_data.h"
#include "check.h"
#include "options.h"

typedef struct {
    double d;
    float f;
    float joints[3];
    uint32_t u;
    int i;
    long l;
    char text[8];
    int flag;
    enum { CHOICE_A, CHOICE_BB, CHOICE_C } choice;
    int special_calls;
} target_t;

static int special(void *t, void *c, const argv_opt_t *o, const char *v, char *err, unsigned long errcap)
{
    (void)o;
    (void)err;
    (void)errcap;
    ((target_t *)t)->special_calls += 1 + (int)strlen(v) + *(int *)c;
    return 0;
}

#define TEST_OPTIONS(X, S)                                                                     \
    X(D, "--d", ARGV_DOUBLE, 0.0, 10.0, 1, 1e-6, 2.0, 1, d, NULL)                                   \
    X(F, "--f", ARGV_FLOAT, -1.0, 1.0, 0, 1.0, 0.5, 1, f, NULL)                                     \
    X(J, "--j", ARGV_FLOATS, 0.0, 5.0, 0, 1.0, 0.25, 1, joints, NULL)                              \
    X(U, "--u", ARGV_UINT32, 1.0, 100.0, 0, 1.0, 3.0, 1, u, NULL)                                  \
    X(I, "--i", ARGV_INT, -5.0, 5.0, 0, 1.0, 0.0, 0, i, NULL)                                      \
    X(L, "--l", ARGV_LONG, 1.0, 1e9, 0, 1.0, 0.0, 0, l, NULL)                                      \
    X(T, "--t", ARGV_TEXT, 0.0, 0.0, 0, 1.0, 0.0, 0, text, NULL)                                   \
    X(G, "--g", ARGV_FLAG, 0.0, 0.0, 0, 1.0, 0.0, 1, flag, NULL)                                   \
    X(C, "--c", ARGV_CHOICE, 0.0, 2.0, 0, 1.0, 1.0, 1, choice, ((const char *const[]){"a", "bb", "c", NULL})) \
    S(SP, "--s", special)

#define ROW(...) ARGV_ROW(target_t, __VA_ARGS__)
static const argv_opt_t k_table[] = {TEST_OPTIONS(ROW, ARGV_SPECIAL_ROW)};
enum { TEST_OPTIONS(ARGV_ID, ARGV_ID) N_ROWS };

static int parse(target_t *t, unsigned char *given, char *err, int argc, char **argv)
{
    int ctx = 10;
    memset(t, 0, sizeof(*t));
    argv_defaults(k_table, N_ROWS, t);
    return argv_parse(argc, argv, k_table, N_ROWS, t, &ctx, given, err, 256);
}

static void test_table(void)
{
    target_t t;
    unsigned char given[N_ROWS];
    char err[256] = "";
    char *none[] = {"prog"};
    CHECK(parse(&t, given, err, 1, none) == 0);
    CHECK(t.d == 2.0 * 1e-6 && t.f == 0.5f && t.joints[0] == 0.25f && t.joints[2] == 0.25f && t.u == 3u);
    CHECK(t.flag == 0 && t.special_calls == 0 && given[ARGV_OPT_D] == 0 && t.choice == CHOICE_BB);

    char *all[] = {"prog", "--d", "5", "--f", "-1", "--j", "4.5", "--u", "100", "--i", "-5", "--l", "7",
                   "--t", "abcdefg", "--g", "--s", "xyz", "--c", "c"};
    CHECK(parse(&t, given, err, (int)(sizeof(all) / sizeof(all[0])), all) == 0);
    CHECK(t.d == 5.0 * 1e-6 && t.f == -1.0f && t.joints[1] == 4.5f && t.u == 100u && t.i == -5 && t.l == 7);
    CHECK(strcmp(t.text, "abcdefg") == 0 && t.flag == 1 && t.special_calls == 1 + 3 + 10);
    CHECK(given[ARGV_OPT_D] && given[ARGV_OPT_G] && given[ARGV_OPT_SP] && t.choice == CHOICE_C);

    struct { char *argv[3]; const char *msg; } bad[] = {
        {{"prog", "--d", "0"}, "--d: '0' is not a number in (0, 10]"},
        {{"prog", "--f", "1.5"}, "--f: '1.5' is not a number in [-1, 1]"},
        {{"prog", "--u", "2.5"}, "--u: '2.5' is not a whole number"},
        {{"prog", "--u", "x"}, "--u: 'x' is not a number in [1, 100]"},
        {{"prog", "--t", "abcdefgh"}, "--t: value longer than 7 characters"},
        {{"prog", "--nope", "1"}, "unknown option '--nope' (see --help)"},
        {{"prog", "nope", "1"}, "unexpected argument 'nope' (options start with --)"},
        {{"prog", "--j", "nan"}, "--j: 'nan' is not a number in [0, 5]"},
        {{"prog", "--c", "b"}, "--c: 'b' is not a, bb or c"},
    };
    for (size_t k = 0; k < sizeof(bad) / sizeof(bad[0]); ++k) {
        CHECK(parse(&t, given, err, 3, bad[k].argv) == -1);
        CHECK_MSG(strcmp(err, bad[k].msg) == 0, "got '%s', want '%s'", err, bad[k].msg);
    }
    char *missing[] = {"prog", "--d"};
    CHECK(parse(&t, given, err, 2, missing) == -1 && strcmp(err, "--d: missing value") == 0);
    char *help[] = {"prog", "--d", "1", "-h", "--nope"};
    CHECK(parse(&t, given, err, 5, help) == 1);
}

static void test_controller_defaults_are_the_registrys(void)
{
    static options_t opt;
    static arm_ctl_config_t core;
    char err[512] = "";
    char *none[] = {"arm_controller"};
    CHECK(options_parse(1, none, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == 0);
    arm_ctl_default_config(&ARM_ROBOT_MODEL, &core);
    CHECK(memcmp(&opt.ctl, &core, sizeof(core)) == 0); /* the port adds nothing of its own */
    CHECK(opt.duration_s == ARM_P_CONTROLLER_DURATION_DEFAULT && opt.rate_hz == ARM_P_CONTROLLER_RATE_DEFAULT);
    CHECK(opt.ref_hold_s == ARM_P_CONTROLLER_REF_HOLD_DEFAULT);
    CHECK(opt.boot_timeout_s == ARM_P_CONTROLLER_BOOT_TIMEOUT_DEFAULT);
    CHECK(opt.ctl.kp == (float)ARM_P_CONTROLLER_KP_DEFAULT && opt.ctl.watchdog_periods == 3u);
    CHECK(opt.stop_timeout_s == ARM_P_CONTROLLER_STOP_TIMEOUT_DEFAULT && opt.ctl.safe_stop_rate == (float)ARM_P_SAFE_STOP_HOLD_RATE);
    CHECK(opt.ctl.following_error_limit[ARM_N_JOINTS - 1] == (float)ARM_P_CONTROLLER_MAX_FOLLOWING_ERROR_DEFAULT);
    CHECK(strcmp(opt.lcm_url, ARM_P_CONTROLLER_LCM_URL_DEFAULT) == 0 && strcmp(opt.bus, ARM_P_CONTROLLER_BUS_DEFAULT) == 0);
    CHECK(opt.steps == (uint32_t)((ARM_P_CONTROLLER_DURATION_DEFAULT + ARM_P_CONTROLLER_REF_HOLD_DEFAULT) *
                                  ARM_P_CONTROLLER_RATE_DEFAULT + 0.5));
    CHECK(strcmp(arm_state_str(ARM_STATE_SAFE_STOP), "safe-stop") == 0 && strcmp(arm_state_str((arm_state_t)9), "?") == 0);
}

static void test_controller_options(void)
{
    static options_t opt;
    char err[512] = "";
    char *a[] = {"arm_controller", "--rate", "500", "--position-margin", "0", "--max-velocity", "3",
                 "--torque-mismatch", "0.5", "--ref-amp", "0,0,0,0,0,0", "--ref-freq", "0,0,0,0,0,0", "--cpu", "0"};
    CHECK(options_parse((int)(sizeof(a) / sizeof(a[0])), a, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == 0);
    CHECK(opt.ctl.period_s == (float)(1.0 / 500.0) && opt.ref_given == 1 && opt.rt.cpu == 0);
    CHECK(opt.ctl.velocity_limit[0] == 3.0f && opt.ctl.torque_mismatch_limit[0] == 0.5f * ARM_ROBOT_MODEL.link[0].torque_limit);
    /* the rate limit scales with the period unless given */
    CHECK(fabsf(opt.ctl.torque_rate_limit[0] - ARM_ROBOT_MODEL.link[0].torque_limit * (0.002f / 0.010f)) < 1e-4f);
    char *half[] = {"arm_controller", "--ref-amp", "0,0,0,0,0,0"};
    CHECK(options_parse(3, half, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == -1);
    CHECK(strstr(err, "--ref-amp and --ref-freq go together") != NULL);
    char *margin[] = {"arm_controller", "--position-margin", "11"};
    CHECK(options_parse(3, margin, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == -1);
    CHECK_MSG(strcmp(err, "--position-margin: '11' is not a number in [0, 10]") == 0, "%s", err);
    /* the safe stop holds the arm: a rate of its own, or the registry's; zero torque alone is refused */
    char *hold[] = {"arm_controller", "--safe-stop", "hold:35", "--stop-timeout", "0.5"};
    CHECK(options_parse(5, hold, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == 0);
    CHECK(opt.ctl.safe_stop_rate == 35.0f && opt.stop_timeout_s == 0.5);
    char *plain[] = {"arm_controller", "--safe-stop", "hold"};
    CHECK(options_parse(3, plain, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == 0);
    CHECK(opt.ctl.safe_stop_rate == (float)ARM_P_SAFE_STOP_HOLD_RATE);
    char *zero[] = {"arm_controller", "--safe-stop", "zero"};
    CHECK(options_parse(3, zero, &ARM_ROBOT_MODEL, &opt, err, sizeof(err)) == -1);
    CHECK_MSG(strstr(err, "--safe-stop: 'zero' is not hold or hold:RATE") == err, "%s", err);
}

int main(void)
{
    test_table();
    test_controller_defaults_are_the_registrys();
    test_controller_options();
    TEST_MAIN_END();
}
