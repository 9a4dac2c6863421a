/* hal_test.h - the HAL for host tests and the fuzzer: simulated hardware in
 * process, a virtual clock the test moves, and a log of every output change. */
#ifndef FACETTE_HAL_TEST_H
#define FACETTE_HAL_TEST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "hal.h"

#define TH_MAX_EVENTS 4096
#define TH_PAGE 1024u

typedef enum { TH_EV_LED, TH_EV_SHUTTER, TH_EV_FOCUS } th_ev_kind_t;
typedef struct {
    uint64_t t;        /* virtual us since boot */
    th_ev_kind_t kind;
    int a;             /* LED: channel (-1 off); lines: level */
    unsigned b;        /* LED: sink mA; shutter: frame index */
    hal_frame_tag_t tag;
} th_event_t;

typedef struct {
    /* clock */
    uint64_t now;
    bool timer_armed;
    uint64_t timer_at;
    /* uart */
    uint8_t rx[1024];
    uint32_t rx_gap[1024];
    size_t rx_len, rx_pos;
    uint32_t idle_us;
    uint8_t tx[1024];
    size_t tx_len;
    /* outputs */
    int led_ch;
    uint16_t dac;
    bool shutter, focus, status;
    hal_frame_tag_t tag;
    uint64_t led_lit_at;   /* when the LED now lit was switched on (a new channel is a new pulse) */
    size_t n_ev;           /* events in ev[] (the last member, so a reset need not clear it) */
    /* inputs */
    bool button;
    int32_t ntc_cC, supply_mV;
    uint8_t led_fault[16]; /* 0 ok, 1 open, 2 short */
    bool auto_sync;        /* a camera answering each shutter opening */
    uint32_t sync_delay_us;
    unsigned miss_sync;    /* next n openings give no sync */
    uint64_t sync_q[16];
    unsigned sync_n;
    /* flash: budget of bytes erased/programmed before the power dies (-1: none) */
    uint8_t flash[2][TH_PAGE];
    long flash_budget;
    /* system */
    hal_reset_cause_t cause;
    uint32_t boots;
    bool reboot;
    unsigned wdt_kicks;
    /* how th_advance runs the main loop, and what it calls after each step */
    uint32_t poll_us;                         /* fw_poll at least this often (500 by default) */
    void (*step_hook)(void);                  /* after each fw_poll and fw_on_timer (NULL: none) */
    void (*led_hook)(int prev_ch, uint16_t prev_dac); /* after each LED select or DAC change */
    void (*adc_hook)(void);                   /* before each ADC read: an interrupt mid-poll */
    th_event_t ev[TH_MAX_EVENTS];
} th_t;

extern th_t th;

/* Fresh hardware (flash erased) and fw_init(). */
void th_fresh(void);
/* Reset: outputs low, flash and inputs kept, fw_init() with the given cause. */
void th_boot(hal_reset_cause_t cause);
/* Move virtual time forward by us, firing the timer exactly at its deadlines
 * and calling fw_poll() at least every th.poll_us. */
void th_advance(uint64_t us);
/* Run until the sequencer state is `state` or max_us passed; true if reached. */
bool th_run_until_state(unsigned state, uint64_t max_us);
/* Deliver one frame on the UART (bytes back to back after a long silence),
 * let the line go idle for 4 ms and return the answer length (0: none). */
size_t th_transact(const uint8_t *req, size_t len, uint8_t *resp);
/* Same with the CRC appended to the first len bytes of req (req needs 2 spare). */
size_t th_transact_crc(uint8_t *req, size_t len, uint8_t *resp);
/* Helpers: return 0 on success or the Modbus exception code; -1 no answer. */
int th_write(uint16_t addr, uint16_t value);
int th_write32(uint16_t addr, uint32_t value);
int th_read(uint8_t fc, uint16_t addr, uint16_t n, uint16_t *out);
uint16_t th_reg_in(uint16_t addr);   /* one input register (asserts success) */
uint16_t th_reg_hold(uint16_t addr); /* one holding register */
uint32_t th_reg_in32(uint16_t addr);

#endif
