/* safe.c - latched faults and their log, temperature derating, current and
 * pulse limits, host watchdog, hardware watchdog. */
#include "fw_core.h"

#define SAFE_BLOCKING_MASK                                                            \
    ((1u << FW_FAULT_OVERTEMP) | (1u << FW_FAULT_LED_OPEN) | (1u << FW_FAULT_LED_SHORT) | \
     (1u << FW_FAULT_SYNC_MISSED) | (1u << FW_FAULT_MAX_PULSE) | (1u << FW_FAULT_SUPPLY_LOW))

static bool s_derating;
static uint64_t s_last_host, s_last_sample;
static bool s_sampled;
static uint16_t s_log_count;

uint32_t safe_now_ms(void) { return (uint32_t)(hal_time_us() / 1000u); }

void safe_init(void)
{
    s_derating = false;
    s_sampled = false;
    s_log_count = 0;
    s_last_host = hal_time_us();
    if (hal_reset_cause() == HAL_RESET_WATCHDOG)
        safe_fault(FW_FAULT_WATCHDOG_RESET, 0);
}

void safe_fault(unsigned code, uint16_t detail)
{
    uint32_t bit = 1u << code;
    unsigned i = s_log_count % FW_CFG_FAULT_LOG_LEN;
    hal_critical_enter();
    mb_reg_set(FW_SLOT_FAULT_BITS, mb_reg_get(FW_SLOT_FAULT_BITS) | bit);
    mb_reg_set(FW_SLOT_FAULT_LOG_CODE + i, code);
    mb_reg_set(FW_SLOT_FAULT_LOG_DETAIL + i, detail);
    mb_reg_set(FW_SLOT_FAULT_LOG_TIME_MS + i, safe_now_ms());
    s_log_count++;
    mb_reg_set(FW_SLOT_FAULT_LOG_COUNT, s_log_count);
    if (bit & SAFE_BLOCKING_MASK) {
        led_off();
        trig_shutter(false);
        trig_focus(false);
        mb_reg_set(FW_SLOT_MANUAL_CHANNEL, (uint32_t)-1);
        seq_on_fault();
    }
    hal_critical_exit();
}

bool safe_blocking_fault(void)
{
    return (mb_reg_get(FW_SLOT_FAULT_BITS) & SAFE_BLOCKING_MASK) != 0;
}

void safe_clear(void)
{
    mb_reg_set(FW_SLOT_FAULT_BITS, 0);
    s_sampled = false; /* re-check the conditions at once */
}

bool safe_derating(void) { return s_derating; }

void fw_host_seen(void) { s_last_host = hal_time_us(); }

void safe_poll(void)
{
    uint64_t now = hal_time_us();
    if (!s_sampled || now - s_last_sample >= FW_CFG_SAFE_SAMPLE_US) {
        s_sampled = true;
        s_last_sample = now;
        int32_t t = hal_adc_read(HAL_ADC_NTC_CENTI_C);
        int32_t mv = hal_adc_read(HAL_ADC_SUPPLY_MV);
        mb_reg_set(FW_SLOT_LED_TEMP_CC, (uint32_t)(t < -32768 ? -32768 : t > 32767 ? 32767 : t));
        mb_reg_set(FW_SLOT_SUPPLY_MV, (uint32_t)(mv < 0 ? 0 : mv > 65535 ? 65535 : mv));
        s_derating = t >= mb_reg_get_i(FW_SLOT_TEMP_DERATE_CC);
        if (t >= mb_reg_get_i(FW_SLOT_TEMP_FAULT_CC) &&
            !(mb_reg_get(FW_SLOT_FAULT_BITS) & (1u << FW_FAULT_OVERTEMP)))
            safe_fault(FW_FAULT_OVERTEMP, (uint16_t)t);
        if (led_channel() >= 0 && mv < (int32_t)FW_CFG_SUPPLY_MIN_MV)
            safe_fault(FW_FAULT_SUPPLY_LOW, (uint16_t)(mv < 0 ? 0 : mv));
    }
    /* maximum on-time per pulse, whoever switched the LED on */
    uint32_t max_pulse = mb_reg_get(FW_SLOT_MAX_PULSE_US);
    if (max_pulse > FW_CFG_HARD_MAX_PULSE_US)
        max_pulse = FW_CFG_HARD_MAX_PULSE_US;
    if (led_channel() >= 0 && now - led_on_since_us() > max_pulse)
        safe_fault(FW_FAULT_MAX_PULSE, (uint16_t)led_channel());
    /* host watchdog: outside a scan, a silent host must not leave a light on */
    uint32_t wd_ms = mb_reg_get(FW_SLOT_HOST_WATCHDOG_MS);
    if (wd_ms && !seq_active() && led_channel() >= 0 && now - s_last_host > (uint64_t)wd_ms * 1000u) {
        led_off();
        mb_reg_set(FW_SLOT_MANUAL_CHANNEL, (uint32_t)-1);
        safe_fault(FW_FAULT_HOST_SILENT, 0);
    }
    hal_watchdog_kick();
}
