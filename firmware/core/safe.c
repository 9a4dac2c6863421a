/* safe.c - latched faults and their log, temperature derating, current and
 * pulse limits, host watchdog, hardware watchdog. */
#include "safe.h"

#include "fw_config.h"
#include "fw_registers.h"
#include "hal.h"
#include "regs.h"

#define SAFE_BLOCKING_MASK                                                            \
    ((1u << FW_FAULT_OVERTEMP) | (1u << FW_FAULT_LED_OPEN) | (1u << FW_FAULT_LED_SHORT) | \
     (1u << FW_FAULT_SYNC_MISSED) | (1u << FW_FAULT_MAX_PULSE) | (1u << FW_FAULT_SUPPLY_LOW))

static bool s_derating;
static uint64_t s_last_host, s_last_sample;
static bool s_sampled;
static uint16_t s_log_count;
static const safe_hooks_t *s_hooks;

static uint32_t now_ms(void) { return (uint32_t)(hal_time_us() / 1000u); }

uint32_t safe_max_current_mA(void)
{
    uint32_t lim = regs_get(FW_SLOT_MAX_CURRENT_MA);
    return lim > FW_CFG_HARD_MAX_MA ? FW_CFG_HARD_MAX_MA : lim;
}

uint32_t safe_max_pulse_us(void)
{
    uint32_t lim = regs_get(FW_SLOT_MAX_PULSE_US);
    return lim > FW_CFG_HARD_MAX_PULSE_US ? FW_CFG_HARD_MAX_PULSE_US : lim;
}

void safe_init(const safe_hooks_t *hooks)
{
    s_hooks = hooks;
    s_derating = false;
    s_sampled = false;
    s_log_count = 0;
    s_last_host = hal_time_us();
    if (hal_reset_cause() == HAL_RESET_WATCHDOG)
        safe_fault(FW_FAULT_WATCHDOG_RESET, 0);
}

static void latch(unsigned code, uint16_t detail, safe_action_t action)
{
    uint32_t bit = 1u << code;
    unsigned i = s_log_count % FW_CFG_FAULT_LOG_LEN;
    hal_critical_enter();
    regs_set(FW_SLOT_FAULT_BITS, regs_get(FW_SLOT_FAULT_BITS) | bit);
    regs_set(FW_SLOT_FAULT_LOG_CODE + i, code);
    regs_set(FW_SLOT_FAULT_LOG_DETAIL + i, detail);
    regs_set(FW_SLOT_FAULT_LOG_TIME_MS + i, now_ms());
    s_log_count++;
    regs_set(FW_SLOT_FAULT_LOG_COUNT, s_log_count);
    s_hooks->on_fault(action);
    hal_critical_exit();
}

void safe_fault(unsigned code, uint16_t detail)
{
    latch(code, detail, ((1u << code) & SAFE_BLOCKING_MASK) ? SAFE_STOP : SAFE_KEEP_GOING);
}

bool safe_blocking_fault(void)
{
    return (regs_get(FW_SLOT_FAULT_BITS) & SAFE_BLOCKING_MASK) != 0;
}

void safe_clear(void)
{
    regs_set(FW_SLOT_FAULT_BITS, 0);
    s_sampled = false; /* re-check the conditions at once */
}

bool safe_derating(void) { return s_derating; }

void safe_host_seen(void) { s_last_host = hal_time_us(); }

void safe_poll(void)
{
    uint64_t now = hal_time_us();
    if (!s_sampled || now - s_last_sample >= FW_CFG_SAFE_SAMPLE_US) {
        s_sampled = true;
        s_last_sample = now;
        int32_t t = hal_adc_read(HAL_ADC_NTC_CENTI_C);
        int32_t mv = hal_adc_read(HAL_ADC_SUPPLY_MV);
        regs_set(FW_SLOT_LED_TEMP_CC, (uint32_t)(t < -32768 ? -32768 : t > 32767 ? 32767 : t));
        regs_set(FW_SLOT_SUPPLY_MV, (uint32_t)(mv < 0 ? 0 : mv > 65535 ? 65535 : mv));
        s_derating = t >= regs_get_i(FW_SLOT_TEMP_DERATE_CC);
        if (t >= regs_get_i(FW_SLOT_TEMP_FAULT_CC) &&
            !(regs_get(FW_SLOT_FAULT_BITS) & (1u << FW_FAULT_OVERTEMP)))
            safe_fault(FW_FAULT_OVERTEMP, (uint16_t)t);
        if (s_hooks->lit_channel() >= 0 && mv < (int32_t)FW_CFG_SUPPLY_MIN_MV)
            safe_fault(FW_FAULT_SUPPLY_LOW, (uint16_t)(mv < 0 ? 0 : mv));
    }
    /* maximum on-time per pulse, whoever switched the LED on. The channel, its
     * start and the clock are read together: the timer interrupt may light an
     * LED after `now` was read, and `now - since` would then wrap to 2^64 us. */
    hal_critical_enter();
    int lit = s_hooks->lit_channel();
    uint64_t since = s_hooks->lit_since_us();
    uint64_t lit_now = hal_time_us();
    hal_critical_exit();
    if (lit >= 0 && lit_now > since && lit_now - since > safe_max_pulse_us())
        safe_fault(FW_FAULT_MAX_PULSE, (uint16_t)lit);
    /* host watchdog: outside a scan, a silent host must not leave a light on */
    uint32_t wd_ms = regs_get(FW_SLOT_HOST_WATCHDOG_MS);
    if (wd_ms && !s_hooks->scan_active() && s_hooks->lit_channel() >= 0 &&
        now - s_last_host > (uint64_t)wd_ms * 1000u)
        latch(FW_FAULT_HOST_SILENT, 0, SAFE_LIGHT_OFF);
    hal_watchdog_kick();
}
