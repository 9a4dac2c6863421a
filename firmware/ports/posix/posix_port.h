/* posix_port.h - the simulated device's port state shared by hal_posix.c and main.c. */
#ifndef FACETTE_POSIX_PORT_H
#define FACETTE_POSIX_PORT_H

#include <stdbool.h>
#include <stdint.h>

#include "hal.h"

#define POSIX_FLASH_PAGE 2048u

/* Called by main.c. */
int posix_open(const char *link_path, const char *side_path, const char *state_dir, double speed);
void posix_boot(hal_reset_cause_t cause); /* (re)start the core */
void posix_step(void);                    /* one main-loop iteration */
bool posix_reboot_requested(void);
void posix_close(void);
extern volatile int posix_stop;

#endif
