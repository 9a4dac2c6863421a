/* nvm.h - calibration store in two flash pages. */
#ifndef FACETTE_NVM_H
#define FACETTE_NVM_H

#include <stddef.h>
#include <stdint.h>

#include "fw_config.h"
#include "fw_err.h"

typedef struct {
    uint32_t seq;    /* 0 = nothing stored */
    uint32_t serial;
    uint16_t gain[FW_CFG_MAX_LEDS];
} nvm_cal_t;
/* Load the newest valid record (FW_OK) or defaults (FW_ERR_FLASH, seq 0). */
fw_err_t nvm_load(nvm_cal_t *cal);
/* Store cal with sequence number cal->seq + 1 in the page not holding the
 * current record; on success cal->seq is updated. */
fw_err_t nvm_save(nvm_cal_t *cal);
uint32_t nvm_crc32(const void *data, size_t len);

#endif
