/* fw_core.h - interfaces between the core's modules (not part of the HAL). */
#ifndef FACETTE_FW_CORE_H
#define FACETTE_FW_CORE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fw_config.h"
#include "fw_err.h"
#include "fw_registers.h"
#include "hal.h"

/* ---- mb_regs: the register store (one value slot per register) ---------- */
void mb_reg_init(void);                         /* every slot to its default */
uint32_t mb_reg_get(unsigned slot);             /* raw value (i16 sign-extended) */
int32_t mb_reg_get_i(unsigned slot);
void mb_reg_set(unsigned slot, uint32_t value); /* internal update, no checks */
/* Wire access, big-endian register bytes. Read: every address must exist in
 * that space (else FW_ERR_ADDRESS). Write (holding space): every address must
 * exist, u32 written whole (else FW_ERR_ADDRESS), every value in range (else
 * FW_ERR_VALUE), then fw_reg_check() for each value; only if all pass are the
 * values stored and fw_reg_apply() called. */
fw_err_t mb_reg_read(fw_reg_space_t space, uint16_t addr, uint16_t qty, uint8_t *out);
fw_err_t mb_reg_write(uint16_t addr, uint16_t qty, const uint8_t *in);

/* ---- mb: Modbus RTU server -------------------------------------------------- */
uint16_t mb_crc16(const uint8_t *data, size_t len);
/* Serve one complete RTU frame (address..CRC). Writes the answer (with CRC)
 * to resp (>= FW_CFG_MB_MAX_FRAME bytes) and returns its length, 0 = no answer. */
size_t mb_handle_frame(const uint8_t *req, size_t len, uint8_t *resp);
uint8_t mb_exception_for(fw_err_t err);
void mb_init(void);
void mb_poll(void); /* read the UART, frame, answer */

/* ---- fw: glue (fw.c) ---------------------------------------------------- */
fw_err_t fw_reg_check(unsigned slot, uint32_t value);
fw_err_t fw_reg_apply(unsigned slot, uint32_t value);
void fw_refresh_inputs(void);  /* bring live input registers up to date */
void fw_host_seen(void);       /* a valid request reached us */
bool fw_reboot_pending(void);

/* ---- led: constant-current sink ---------------------------------------- */
void led_init(void);
/* Light channel ch at set_mA before gain; returns the sink current set (mA),
 * after gain, derating and the current limits. */
uint16_t led_on(int ch, uint16_t set_mA);
void led_off(void);
int led_channel(void);
uint16_t led_sink_mA(void);
uint64_t led_on_since_us(void);
/* Sink current for ch at set_mA (gain, derating, limits), without lighting. */
uint16_t led_sink_for(int ch, uint16_t set_mA, bool derated);
/* Read the current sense while lit; FW_ERR_FAULT after latching LED_OPEN or
 * LED_SHORT when it disagrees with the setpoint. *meas_mA gets the reading. */
fw_err_t led_check(uint16_t *meas_mA);

/* ---- trig: camera lines, flash sync, button ----------------------------- */
void trig_init(void);
void trig_shutter(bool active);
void trig_focus(bool active);
void trig_sync_flush(void);
/* Earliest sync edge at or after t_from; true if one was captured. */
bool trig_sync_seen(uint64_t t_from, uint64_t *t_edge);
/* Debounced button: returns true once per press. */
bool trig_button_pressed(void);

/* ---- safe: faults, limits, watchdogs ------------------------------------ */
void safe_init(void);
void safe_poll(void);
/* Latch fault code (FW_FAULT_*), log it with detail, switch lights off and put
 * the sequencer into FAULT when the fault is blocking. */
void safe_fault(unsigned code, uint16_t detail);
bool safe_blocking_fault(void);
void safe_clear(void);
bool safe_derating(void);
uint32_t safe_now_ms(void);

/* ---- seq: scan sequencer -------------------------------------------------- */
void seq_init(void);
fw_err_t seq_command(unsigned cmd);     /* ARM..RESUME; FW_ERR_STATE if not now */
fw_err_t seq_command_check(unsigned cmd);
void seq_on_timer(void);
void seq_on_fault(void);
void seq_update_status(void);           /* state, progress, time left -> registers */
unsigned seq_state(void);
bool seq_active(void);                  /* ARMED, RUNNING or PAUSED */
/* Scan config check as done at ARM (FW_OK or FW_ERR_CONFIG). */
fw_err_t seq_validate_config(void);

/* ---- nvm: calibration store (two flash pages) --------------------------- */
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
