/*
 * hal.h - the whole hardware boundary of the facette firmware.
 *
 * The portable core (firmware/core/) calls only the functions declared here; a
 * port (firmware/ports/<name>/) implements them and nothing else differs between
 * ports. No vendor header may be included above ports/.
 *
 * Conventions
 *   - Return values of type int: 0 = success, negative = failure (the core maps
 *     them to its own fw_err_t).
 *   - Times are microseconds on the port's monotonic clock (hal_time_us). The
 *     posix port runs this clock in virtual time (possibly faster than real time).
 *   - Functions marked [ISR-safe] may be called from hal_timer callbacks.
 *
 * Callbacks the core provides (the port calls them):
 *   fw_init()      once after reset, after the port has initialised its hardware;
 *   fw_poll()      repeatedly from the port's main loop (never from an interrupt);
 *   fw_on_timer()  when the one-shot timer armed with hal_timer_start() expires
 *                  (interrupt context on a real MCU; the core keeps it short).
 */
#ifndef FACETTE_HAL_H
#define FACETTE_HAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- callbacks implemented by the core ---------------------------------- */
void fw_init(void);
void fw_poll(void);
void fw_on_timer(void);

/* ---- UART (Modbus RTU line, 8N1) ----------------------------------------- */
/* Line speed in bit/s (115200 by default); the core derives the 1.5- and
 * 3.5-character times from it (fixed 750/1750 us above 19200 bit/s). */
uint32_t hal_uart_baud(void);
/* Next received byte (0..255), or -1 when none is pending. *gap_us receives the
 * line silence that preceded this byte, measured on the line's own time base
 * (the port timestamps bytes at reception; the core never guesses from polling). */
int hal_uart_getc(uint32_t *gap_us);
/* Line silence since the last received byte, same time base as gap_us
 * (UINT32_MAX if nothing was ever received). */
uint32_t hal_uart_idle_us(void);
/* Queue len bytes for transmission; may block until they are queued. */
void hal_uart_write(const uint8_t *data, size_t len);

/* ---- clock and one-shot timer ------------------------------------------- */
/* Monotonic microseconds since reset. [ISR-safe] */
uint64_t hal_time_us(void);
/* Arm the single one-shot timer for absolute time at_us (re-arming replaces the
 * previous deadline; a deadline in the past fires as soon as possible). When it
 * expires the port calls fw_on_timer(). [ISR-safe] */
void hal_timer_start(uint64_t at_us);
/* Disarm the timer (no callback afterwards). [ISR-safe] */
void hal_timer_cancel(void);

/* ---- GPIO ---------------------------------------------------------------- */
typedef enum {
    HAL_LINE_SHUTTER = 0, /* camera release (active = 1 = pressed) */
    HAL_LINE_FOCUS = 1,   /* camera half-press / autofocus (active = 1) */
    HAL_LINE_STATUS = 2,  /* front-panel status LED */
    HAL_LINE_COUNT
} hal_line_t;
/* Drive an output line. [ISR-safe] */
void hal_gpio_write(hal_line_t line, bool active);
/* Switch exactly one LED channel into the current sink, or none (ch < 0).
 * Channels are 0-based, < FW_CFG_MAX_LEDS. [ISR-safe] */
void hal_led_select(int ch);
/* Raw level of the front-panel button (true = pressed); the core debounces. */
bool hal_button_read(void);
/* Oldest flash-sync (X-sync) edge captured by the port (input capture) and not
 * yet taken, whose timestamp is <= hal_time_us(). Returns true and writes its
 * timestamp to *t_us, or returns false when none is pending. [ISR-safe] */
bool hal_sync_take(uint64_t *t_us);

/* Description of the frame about to be exposed, given just before the shutter
 * line goes active. Hardware ports ignore it; the simulated device forwards it to
 * the rig simulator. mode: 0 camera-timed, 1 bulb, 2 LED-defined. [ISR-safe] */
typedef struct {
    uint16_t frame;    /* frame index within the scan (0-based) */
    uint16_t light;    /* light index (position in the scan order) */
    uint16_t exposure; /* exposure index */
    uint8_t mode;
    uint32_t exp_us;   /* configured exposure (camera/bulb) or LED pulse (led) */
} hal_frame_tag_t;
void hal_frame_annotate(const hal_frame_tag_t *tag);

/* ---- LED current sink (DAC) ---------------------------------------------- */
/* Set the constant-current sink's DAC code, 0..FW_CFG_DAC_MAX_CODE; the sink
 * current is code * FW_CFG_DAC_FULL_SCALE_MA / FW_CFG_DAC_MAX_CODE. [ISR-safe] */
void hal_dac_set(uint16_t code);

/* ---- ADC (calibrated by the port, which knows its shunt and dividers) ----- */
typedef enum {
    HAL_ADC_LED_CURRENT_MA = 0, /* current through the sink, mA */
    HAL_ADC_NTC_CENTI_C = 1,    /* LED heat-sink temperature, 0.01 degC */
    HAL_ADC_SUPPLY_MV = 2,      /* LED supply voltage, mV */
    HAL_ADC_COUNT
} hal_adc_t;
/* One conversion of channel ch in the unit given above. [ISR-safe] */
int32_t hal_adc_read(hal_adc_t ch);

/* ---- flash: two pages reserved for the calibration store ----------------- */
/* Size in bytes of each of the two pages (>= 256, multiple of 4). */
uint32_t hal_flash_page_size(void);
/* Erase page (0 or 1) to 0xFF. */
int hal_flash_erase(unsigned page);
/* Program len bytes at offset; offset and len multiples of 4; the target must
 * be erased (a port may refuse to program a non-erased word). */
int hal_flash_write(unsigned page, uint32_t offset, const void *data, size_t len);
/* Read len bytes at offset. */
int hal_flash_read(unsigned page, uint32_t offset, void *data, size_t len);

/* ---- system --------------------------------------------------------------- */
typedef enum {
    HAL_RESET_POWER_ON = 0,
    HAL_RESET_PIN = 1,
    HAL_RESET_WATCHDOG = 2,
    HAL_RESET_SOFTWARE = 3,
    HAL_RESET_BROWNOUT = 4,
    HAL_RESET_UNKNOWN = 5
} hal_reset_cause_t;
/* Why the MCU last reset. */
hal_reset_cause_t hal_reset_cause(void);
/* Number of starts since the counter was cleared, this one included (kept by
 * the port where it survives resets: backup register, state file...). */
uint32_t hal_boot_count(void);
/* Start (first call) and kick the hardware watchdog (timeout FW_CFG_WDT_MS). */
void hal_watchdog_kick(void);
/* Mask / unmask interrupts; nestable. */
void hal_critical_enter(void);
void hal_critical_exit(void);
/* Reset the MCU. A real port never returns; the posix port returns and restarts
 * the core from its main loop, so the caller must return promptly. */
void hal_reboot(void);
/* 32-bit unique id of this unit (serial number fallback when none is stored). */
uint32_t hal_unique_id(void);

#ifdef __cplusplus
}
#endif
#endif /* FACETTE_HAL_H */
