/* main.c - the simulated facette device (firmware posix port).
 *
 *   facette-device [--link PATH] [--speed X] [--side SOCKET] [--state DIR]
 *
 * First line on stdout: "port: <pty path>". See hal_posix.c for the side channel. */
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "posix_port.h"

static void usage(FILE *f)
{
    fprintf(f, "usage: facette-device [--link PATH] [--speed X] [--side SOCKET] [--state DIR]\n"
               "  --link PATH    also make PATH a symlink to the pseudo-terminal\n"
               "  --speed X      virtual clock runs X times real time (default 1, > 0)\n"
               "  --side SOCKET  listen for the rig simulator on this Unix socket\n"
               "  --state DIR    keep the simulated flash (calibration) and boot count in DIR\n");
}

static void on_signal(int sig)
{
    (void)sig;
    posix_stop = 1;
}

int main(int argc, char **argv)
{
    const char *link_path = NULL, *side = NULL, *state = NULL;
    double speed = 1.0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 0;
        }
        if (i + 1 >= argc) {
            fprintf(stderr, "facette-device: option %s needs a value\n", a);
            usage(stderr);
            return 2;
        }
        const char *v = argv[++i];
        if (!strcmp(a, "--link")) {
            link_path = v;
        } else if (!strcmp(a, "--side")) {
            side = v;
        } else if (!strcmp(a, "--state")) {
            state = v;
        } else if (!strcmp(a, "--speed")) {
            char *end;
            speed = strtod(v, &end);
            if (*end || !(speed > 0) || speed > 1e7) {
                fprintf(stderr, "facette-device: --speed %s: give a number > 0 (and <= 1e7)\n", v);
                return 2;
            }
        } else {
            fprintf(stderr, "facette-device: unknown option %s\n", a);
            usage(stderr);
            return 2;
        }
    }
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);
    if (posix_open(link_path, side, state, speed) != 0)
        return 1;
    posix_boot(HAL_RESET_POWER_ON);
    while (!posix_stop) {
        posix_step();
        if (posix_reboot_requested())
            posix_boot(HAL_RESET_SOFTWARE);
    }
    posix_close();
    return 0;
}
