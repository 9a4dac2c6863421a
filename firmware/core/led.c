/* led.c - constant-current LED drive: DAC setpoint with per-channel gain,
 * one switch per channel, current-sense check (open / short). */
#include "led.h"

#include "fw_config.h"
#include "fw_registers.h"
#include "hal.h"
#include "regs.h"
#include "safe.h"

static int s_ch = -1;
static uint16_t s_sink_mA;
static uint64_t s_on_since;

void led_init(void)
{
    led_off();
}

uint32_t led_gained_mA(unsigned ch, uint16_t set_mA)
{
    uint32_t gain = regs_get(FW_SLOT_CAL_GAIN + ch); /* 1e-4 */
    return ((uint32_t)set_mA * gain + 5000u) / 10000u;
}

/* Sink current for ch at set_mA: gain, derating, limit (0: no such channel). */
static uint16_t sink_for(int ch, uint16_t set_mA, bool derated)
{
    if (ch < 0 || ch >= (int)FW_CFG_MAX_LEDS)
        return 0;
    uint32_t mA = led_gained_mA((unsigned)ch, set_mA);
    if (derated)
        mA = mA * FW_CFG_DERATE_PCT / 100u;
    uint32_t lim = safe_max_current_mA();
    return (uint16_t)(mA > lim ? lim : mA);
}

uint16_t led_on(int ch, uint16_t set_mA)
{
    uint16_t mA = sink_for(ch, set_mA, safe_derating());
    if (mA == 0) {
        led_off();
        return 0;
    }
    uint32_t code = ((uint32_t)mA * FW_CFG_DAC_MAX_CODE + FW_CFG_DAC_FULL_SCALE_MA / 2u) /
                    FW_CFG_DAC_FULL_SCALE_MA;
    hal_critical_enter();
    if (s_ch != ch)
        hal_led_select(-1); /* never two channels, never a channel at the old current */
    hal_dac_set((uint16_t)code);
    hal_led_select(ch);
    if (s_ch != ch)
        s_on_since = hal_time_us();
    s_ch = ch;
    s_sink_mA = mA;
    hal_critical_exit();
    return mA;
}

void led_off(void)
{
    hal_critical_enter();
    hal_led_select(-1);
    hal_dac_set(0);
    s_ch = -1;
    s_sink_mA = 0;
    hal_critical_exit();
}

int led_channel(void) { return s_ch; }
uint16_t led_sink_mA(void) { return s_sink_mA; }
uint64_t led_on_since_us(void) { return s_on_since; }

fw_err_t led_check(uint16_t *meas_mA)
{
    int32_t m = hal_adc_read(HAL_ADC_LED_CURRENT_MA);
    if (m < 0)
        m = 0;
    *meas_mA = (uint16_t)(m > 0xFFFF ? 0xFFFF : m);
    regs_set(FW_SLOT_LED_CURRENT_MA, *meas_mA);
    if (s_ch < 0 || s_sink_mA < FW_CFG_SENSE_MIN_MA)
        return FW_OK;
    if ((uint32_t)m * 100u < (uint32_t)s_sink_mA * FW_CFG_SENSE_OPEN_PCT) {
        safe_fault(FW_FAULT_LED_OPEN, (uint16_t)s_ch);
        return FW_ERR_FAULT;
    }
    if ((uint32_t)m * 100u > (uint32_t)s_sink_mA * FW_CFG_SENSE_SHORT_PCT) {
        safe_fault(FW_FAULT_LED_SHORT, (uint16_t)s_ch);
        return FW_ERR_FAULT;
    }
    return FW_OK;
}
