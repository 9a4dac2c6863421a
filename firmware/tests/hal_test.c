/* hal_test.c - simulated hardware for the host tests and the fuzzer. */
#include "hal_test.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fw_config.h"
#include "fw_registers.h"
#include "mb.h"
#include "regs.h"

th_t th;

static void log_ev(th_ev_kind_t k, int a, unsigned b)
{
    if (th.n_ev < TH_MAX_EVENTS)
        th.ev[th.n_ev++] = (th_event_t){th.now, k, a, b, th.tag};
}

static unsigned dac_mA(uint16_t code)
{
    return (unsigned)(((uint32_t)code * FW_CFG_DAC_FULL_SCALE_MA + FW_CFG_DAC_MAX_CODE / 2u) /
                      FW_CFG_DAC_MAX_CODE);
}

static int s_rep_ch = -1;
static unsigned s_rep_mA;
static void led_report(void)
{
    bool on = th.led_ch >= 0 && th.dac > 0;
    int ch = on ? th.led_ch : -1;
    unsigned mA = on ? dac_mA(th.dac) : 0u;
    if (on && ch != s_rep_ch)
        th.led_lit_at = th.now;
    if (ch != s_rep_ch || mA != s_rep_mA) {
        log_ev(TH_EV_LED, ch, mA);
        s_rep_ch = ch;
        s_rep_mA = mA;
    }
}

uint32_t hal_uart_baud(void) { return 115200u; }
int hal_uart_getc(uint32_t *gap_us)
{
    if (th.rx_pos >= th.rx_len)
        return -1;
    *gap_us = th.rx_gap[th.rx_pos];
    return th.rx[th.rx_pos++];
}
uint32_t hal_uart_idle_us(void) { return th.rx_pos >= th.rx_len ? th.idle_us : 0u; }
void hal_uart_write(const uint8_t *data, size_t len)
{
    if (th.tx_len + len <= sizeof th.tx) {
        memcpy(&th.tx[th.tx_len], data, len);
        th.tx_len += len;
    }
}

uint64_t hal_time_us(void) { return th.now; }
void hal_timer_start(uint64_t at_us)
{
    th.timer_armed = true;
    th.timer_at = at_us;
}
void hal_timer_cancel(void) { th.timer_armed = false; }

void hal_gpio_write(hal_line_t line, bool active)
{
    if (line == HAL_LINE_SHUTTER && active != th.shutter) {
        th.shutter = active;
        log_ev(TH_EV_SHUTTER, active, th.tag.frame);
        if (active && th.auto_sync) {
            if (th.miss_sync)
                th.miss_sync--;
            else if (th.sync_n < 16)
                th.sync_q[th.sync_n++] = th.now + th.sync_delay_us;
        }
    } else if (line == HAL_LINE_FOCUS && active != th.focus) {
        th.focus = active;
        log_ev(TH_EV_FOCUS, active, 0);
    } else if (line == HAL_LINE_STATUS) {
        th.status = active;
    }
}
void hal_led_select(int ch)
{
    int prev_ch = th.led_ch;
    th.led_ch = ch;
    led_report();
    if (th.led_hook)
        th.led_hook(prev_ch, th.dac);
}
void hal_dac_set(uint16_t code)
{
    uint16_t prev_dac = th.dac;
    th.dac = code;
    led_report();
    if (th.led_hook)
        th.led_hook(th.led_ch, prev_dac);
}
bool hal_button_read(void) { return th.button; }
bool hal_sync_take(uint64_t *t_us)
{
    for (unsigned i = 0; i < th.sync_n; i++) {
        if (th.sync_q[i] <= th.now) {
            *t_us = th.sync_q[i];
            th.sync_q[i] = th.sync_q[--th.sync_n];
            return true;
        }
    }
    return false;
}
void hal_frame_annotate(const hal_frame_tag_t *tag) { th.tag = *tag; }

int32_t hal_adc_read(hal_adc_t ch)
{
    if (th.adc_hook)
        th.adc_hook();
    switch (ch) {
    case HAL_ADC_LED_CURRENT_MA: {
        if (th.led_ch < 0 || th.led_ch >= 16)
            return 0;
        int32_t mA = (int32_t)dac_mA(th.dac);
        uint8_t f = th.led_fault[th.led_ch];
        return f == 1 ? 0 : f == 2 ? mA * 16 / 10 : mA;
    }
    case HAL_ADC_NTC_CENTI_C: return th.ntc_cC;
    case HAL_ADC_SUPPLY_MV: return th.supply_mV;
    default: return 0;
    }
}

uint32_t hal_flash_page_size(void) { return TH_PAGE; }
/* The power dies when the budget runs out: the rest of the operation is lost. */
static bool spend(void)
{
    if (th.flash_budget < 0)
        return true;
    if (th.flash_budget == 0)
        return false;
    th.flash_budget--;
    return true;
}
int hal_flash_erase(unsigned page)
{
    if (page > 1)
        return -1;
    for (unsigned i = 0; i < TH_PAGE; i++) {
        if (!spend())
            return -1;
        th.flash[page][i] = 0xFF;
    }
    return 0;
}
int hal_flash_write(unsigned page, uint32_t offset, const void *data, size_t len)
{
    if (page > 1 || offset % 4u || len % 4u || offset + len > TH_PAGE)
        return -1;
    const uint8_t *d = data;
    for (size_t i = 0; i < len; i++) {
        if (!spend())
            return -1;
        th.flash[page][offset + i] &= d[i];
    }
    return memcmp(&th.flash[page][offset], data, len) == 0 ? 0 : -1;
}
int hal_flash_read(unsigned page, uint32_t offset, void *data, size_t len)
{
    if (page > 1 || offset + len > TH_PAGE)
        return -1;
    memcpy(data, &th.flash[page][offset], len);
    return 0;
}

hal_reset_cause_t hal_reset_cause(void) { return th.cause; }
uint32_t hal_boot_count(void) { return th.boots; }
void hal_watchdog_kick(void) { th.wdt_kicks++; }
void hal_critical_enter(void) {}
void hal_critical_exit(void) {}
void hal_reboot(void) { th.reboot = true; }
uint32_t hal_unique_id(void) { return 0xC0FFEE01u; }

void fw_assert_failed(const char *file, int line)
{
    fprintf(stderr, "firmware assertion failed at %s:%d\n", file, line);
    abort();
}

void th_boot(hal_reset_cause_t cause)
{
    th.cause = cause;
    th.boots++;
    th.reboot = false;
    th.timer_armed = false;
    th.rx_len = th.rx_pos = 0;
    th.tx_len = 0;
    th.sync_n = 0;
    th.shutter = th.focus = false;
    th.led_ch = -1;
    th.dac = 0;
    s_rep_ch = -1;
    s_rep_mA = 0;
    th.n_ev = 0;
    th.flash_budget = -1;
    fw_init();
}

void th_fresh(void)
{
    memset(&th, 0, offsetof(th_t, ev)); /* the event log (128 KiB) is only read up to n_ev */
    memset(th.flash, 0xFF, sizeof th.flash);
    th.ntc_cC = 2500;
    th.supply_mV = 12000;
    th.auto_sync = true;
    th.idle_us = 100000;
    th.poll_us = 500;
    th_boot(HAL_RESET_POWER_ON);
}

void th_advance(uint64_t us)
{
    uint64_t end = th.now + us;
    while (th.now < end) {
        uint64_t next = th.now + th.poll_us;
        if (next > end)
            next = end;
        if (th.timer_armed && th.timer_at <= next) {
            if (th.timer_at > th.now)
                th.now = th.timer_at;
            th.timer_armed = false;
            fw_on_timer();
            if (th.step_hook)
                th.step_hook();
            continue;
        }
        th.now = next;
        fw_poll();
        if (th.step_hook)
            th.step_hook();
        if (th.reboot)
            th_boot(HAL_RESET_SOFTWARE);
    }
}

bool th_run_until_state(unsigned state, uint64_t max_us)
{
    uint64_t end = th.now + max_us;
    while (th.now < end) {
        if (regs_get(FW_SLOT_STATE) == state)
            return true;
        th_advance(1000);
    }
    return regs_get(FW_SLOT_STATE) == state;
}

size_t th_transact(const uint8_t *req, size_t len, uint8_t *resp)
{
    if (len > sizeof th.rx)
        len = sizeof th.rx;
    memcpy(th.rx, req, len);
    for (size_t i = 0; i < len; i++)
        th.rx_gap[i] = i == 0 ? 100000u : 0u;
    th.rx_len = len;
    th.rx_pos = 0;
    th.tx_len = 0;
    th.idle_us = 4000;
    fw_poll();
    if (th.step_hook)
        th.step_hook();
    size_t n = th.tx_len;
    memcpy(resp, th.tx, n);
    th.tx_len = 0;
    if (th.reboot)
        th_boot(HAL_RESET_SOFTWARE);
    return n;
}

size_t th_transact_crc(uint8_t *req, size_t len, uint8_t *resp)
{
    uint16_t c = mb_crc16(req, len);
    req[len] = (uint8_t)c;
    req[len + 1] = (uint8_t)(c >> 8);
    return th_transact(req, len + 2, resp);
}

static int answer_code(const uint8_t *resp, size_t n, uint8_t fc)
{
    if (n == 0)
        return -1;
    if (resp[1] == (uint8_t)(fc | 0x80u))
        return resp[2];
    return 0;
}

int th_write(uint16_t addr, uint16_t value)
{
    uint8_t req[8] = {1, 6, (uint8_t)(addr >> 8), (uint8_t)addr, (uint8_t)(value >> 8), (uint8_t)value};
    uint8_t resp[256];
    size_t n = th_transact_crc(req, 6, resp);
    return answer_code(resp, n, 6);
}

int th_write32(uint16_t addr, uint32_t v)
{
    uint8_t req[13] = {1, 16, (uint8_t)(addr >> 8), (uint8_t)addr, 0, 2, 4,
                       (uint8_t)(v >> 24), (uint8_t)(v >> 16), (uint8_t)(v >> 8), (uint8_t)v};
    uint8_t resp[256];
    size_t n = th_transact_crc(req, 11, resp);
    return answer_code(resp, n, 16);
}

int th_read(uint8_t fc, uint16_t addr, uint16_t cnt, uint16_t *out)
{
    uint8_t req[8] = {1, fc, (uint8_t)(addr >> 8), (uint8_t)addr, (uint8_t)(cnt >> 8), (uint8_t)cnt};
    uint8_t resp[300];
    size_t n = th_transact_crc(req, 6, resp);
    int code = answer_code(resp, n, fc);
    if (code == 0)
        for (unsigned i = 0; i < cnt; i++)
            out[i] = (uint16_t)(resp[3 + 2 * i] << 8 | resp[4 + 2 * i]);
    return code;
}

uint16_t th_reg_in(uint16_t addr)
{
    uint16_t v = 0xDEAD;
    if (th_read(4, addr, 1, &v) != 0)
        abort();
    return v;
}

uint16_t th_reg_hold(uint16_t addr)
{
    uint16_t v = 0xDEAD;
    if (th_read(3, addr, 1, &v) != 0)
        abort();
    return v;
}

uint32_t th_reg_in32(uint16_t addr)
{
    uint16_t v[2];
    if (th_read(4, addr, 2, v) != 0)
        abort();
    return (uint32_t)v[0] << 16 | v[1];
}
