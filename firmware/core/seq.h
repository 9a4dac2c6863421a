/* seq.h - the scan sequencer: lights x exposures, timing modes, sync retry,
 * the frame ring. */
#ifndef FACETTE_SEQ_H
#define FACETTE_SEQ_H

#include <stdbool.h>

#include "fw_err.h"

void seq_init(void);
fw_err_t seq_command(unsigned cmd); /* ARM..RESUME; FW_ERR_STATE if not now */
fw_err_t seq_command_check(unsigned cmd);
void seq_on_timer(void);
void seq_on_fault(void);        /* stop at once, state FAULT (lines: the caller) */
void seq_update_status(void);   /* state, progress, time left -> registers */
bool seq_active(void);          /* ARMED, RUNNING or PAUSED */
/* Scan config check as done at ARM (FW_OK or FW_ERR_CONFIG). */
fw_err_t seq_validate_config(void);

#endif
