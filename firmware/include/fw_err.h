/* fw_err.h - the firmware's one error type, and VERIFY / ASSERT.
 * Errors are values: 0 ok, negative errors. The Modbus exception code for each
 * is chosen in one place, mb_exception_for() in core/mb.c. */
#ifndef FACETTE_FW_ERR_H
#define FACETTE_FW_ERR_H

#include "fw_config.h"

typedef enum {
    FW_OK = 0,
    FW_ERR_FUNCTION = -1,   /* function code / sub-function not supported      -> 01 */
    FW_ERR_ADDRESS = -2,    /* no such register, wrong space, half a u32        -> 02 */
    FW_ERR_VALUE = -3,      /* value out of range, bad quantity or byte count   -> 03 */
    FW_ERR_STATE = -4,      /* command not allowed in the current state         -> 04 */
    FW_ERR_LOCKED = -5,     /* calibration write without unlock                 -> 04 */
    FW_ERR_FAULT = -6,      /* a latched fault forbids it (clear faults first)  -> 04 */
    FW_ERR_CONFIG = -7,     /* scan configuration inconsistent (arm refused)    -> 04 */
    FW_ERR_FLASH = -8,      /* flash erase/program/verify failed                -> 04 */
    FW_ERR_CRC = -9,        /* frame CRC wrong: no answer                              */
    FW_ERR_FRAME = -10,     /* malformed frame (too short, inner gap): no answer       */
} fw_err_t;

/* VERIFY: bad input from outside -> return an error value to the caller. */
#define FW_VERIFY(cond, err) \
    do {                     \
        if (!(cond))         \
            return (err);    \
    } while (0)

/* ASSERT: a firmware bug. Halts in debug builds (FW_CFG_ASSERT_HALT). */
void fw_assert_failed(const char *file, int line);
#if FW_CFG_ASSERT_HALT
#define FW_ASSERT(cond)                               \
    do {                                              \
        if (!(cond))                                  \
            fw_assert_failed(__FILE__, __LINE__);     \
    } while (0)
#else
#define FW_ASSERT(cond) ((void)0)
#endif

#endif
