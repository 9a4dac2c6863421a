/* mb.h - Modbus RTU server: CRC, 3.5-character framing, PDU dispatch, the
 * register map's addresses and ranges. It knows the application only through
 * the callbacks below (filled by fw_init, the nanoMODBUS nmbs_callbacks
 * pattern); it calls no other core module but the register map. */
#ifndef FACETTE_MB_H
#define FACETTE_MB_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fw_err.h"

/* Slots and values as in fw_registers.h (i16 sign-extended). */
typedef struct {
    /* Before a read: bring the live input registers up to date. */
    void (*refresh)(void);
    /* The value of one slot, for a read (and for apply, below). */
    uint32_t (*read)(unsigned slot);
    /* Write (holding space), in four passes over the request: every address
     * exists and every u32 is written whole (else FW_ERR_ADDRESS), every value in
     * its register's range (else FW_ERR_VALUE), then check() for each value (its
     * error is the answer); only if all pass, write() stores every value and
     * then apply() runs each one's side effects, in address order, with the
     * value read() gives back at that moment. */
    fw_err_t (*check)(unsigned slot, uint32_t value);
    void (*write)(unsigned slot, uint32_t value);
    fw_err_t (*apply)(unsigned slot, uint32_t value);
    /* A valid request for this unit (or a broadcast) arrived. */
    void (*host_seen)(void);
    /* A request failed with err (the exception answered, or none for a broadcast). */
    void (*failed)(fw_err_t err);
    /* True: stop reading the UART now (a reboot is due after the answer). */
    bool (*stop)(void);
} mb_callbacks_t;

/* Start the framer; cb (kept, not copied) must have every member set. */
void mb_init(const mb_callbacks_t *cb);
void mb_poll(void); /* read the UART, frame, answer */
uint16_t mb_crc16(const uint8_t *data, size_t len);
/* Serve one complete RTU frame (address..CRC). Writes the answer (with CRC)
 * to resp (>= FW_CFG_MB_MAX_FRAME bytes) and returns its length, 0 = no answer. */
size_t mb_handle_frame(const uint8_t *req, size_t len, uint8_t *resp);
/* The exception code answered for err (the one place that chooses it). */
uint8_t mb_exception_for(fw_err_t err);

#endif
