/* test_safe.c - current limits, gain, derating, faults and their log, watchdogs. */
#include "fw_err.h"
#include "fw_registers.h"
#include "hal.h"
#include "led.h"
#include "regs.h"
#include "test.h"

static void unlock(void) { CHECK_EQ(th_write(FW_REG_CAL_UNLOCK, FW_UNLOCK_KEY), 0); }

static void manual(int ch, uint16_t mA)
{
    CHECK_EQ(th_write(FW_REG_MANUAL_CURRENT_MA, mA), 0);
    CHECK_EQ(th_write(FW_REG_MANUAL_CHANNEL, (uint16_t)(int16_t)ch), 0);
}

static unsigned sink_mA(void)
{
    return th.led_ch < 0 ? 0u : (unsigned)((th.dac * 2000u + 2047u) / 4095u);
}

/* An interrupt that lights an LED while safe_poll samples the ADC (once). */
static void light_mid_poll(void)
{
    th.adc_hook = NULL;
    th.now += 20;
    led_on(6, 200);
}

static void short_scan(void)
{
    CHECK_EQ(th_write(FW_REG_TIMING_MODE, FW_TIMING_MODE_BULB), 0);
    CHECK_EQ(th_write(FW_REG_N_LIGHTS, 2), 0);
    CHECK_EQ(th_write(FW_REG_N_EXPOSURES, 1), 0);
    CHECK_EQ(th_write32(FW_REG_EXPOSURE_TIME_US(0), 300000), 0);
}

void test_safe(void)
{
    SHOULD("apply the channel's calibration gain to the current")
    {
        unlock();
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(3), 15000), 0);
        manual(3, 400);
        CHECK_EQ(th.led_ch, 3);
        CHECK_EQ(sink_mA(), 600);
        CHECK_EQ(th_reg_in(FW_REG_LED_SET_MA), 600);
        manual(2, 400);
        CHECK_EQ(sink_mA(), 400);
    }
    SHOULD("never set more than max_current_mA whatever the gain and the request")
    {
        unlock();
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(0), 20000), 0);
        manual(0, 1500);
        CHECK_EQ(sink_mA(), 1000);
        CHECK_EQ(th_write(FW_REG_MAX_CURRENT_MA, 1501), 3); /* hard limit 1500 */
    }
    SHOULD("lower a manual light at once when max_current_mA is lowered below it")
    {
        /* found by fuzz_seq (fuzz/corpus-seq/regress_max_current_lowered_under_a_manual_light):
         * the light stayed at 900 mA under a 300 mA limit until the next manual write */
        manual(2, 900);
        CHECK_EQ(sink_mA(), 900);
        CHECK_EQ(th_write(FW_REG_MAX_CURRENT_MA, 300), 0);
        CHECK_EQ(th.led_ch, 2);
        CHECK_EQ(sink_mA(), 300);
        CHECK_EQ(th_reg_in(FW_REG_LED_SET_MA), 300);
        CHECK_EQ(th_write(FW_REG_MAX_CURRENT_MA, 1000), 0); /* raising it gives back the setpoint */
        CHECK_EQ(sink_mA(), 900);
    }
    SHOULD("halve the current above temp_derate_cC")
    {
        th.ntc_cC = 6500;
        th_advance(20000);
        manual(1, 800);
        CHECK_EQ(sink_mA(), 400);
        CHECK_EQ(th_reg_in(FW_REG_LED_TEMP_CC), 6500);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_IDLE);
    }
    SHOULD("fault OVERTEMP at temp_fault_cC: scan stopped, lights off, logged with the temperature")
    {
        short_scan();
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_START), 0);
        th_advance(50000);
        CHECK(th.led_ch >= 0);
        th.ntc_cC = 8100;
        th_advance(20000);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_FAULT);
        CHECK_EQ(th.led_ch, -1);
        CHECK(!th.shutter);
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_OVERTEMP));
        CHECK_EQ(th_reg_in(FW_REG_FAULT_LOG_CODE(1)), FW_FAULT_OVERTEMP);
        CHECK_EQ(th_reg_in(FW_REG_FAULT_LOG_DETAIL(1)), 8100);
        CHECK(th_reg_in32(FW_REG_FAULT_LOG_TIME_MS(1)) >= 50);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_CLEAR_FAULTS), 0);
        th_advance(20000); /* still hot: faults again */
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_FAULT);
        th.ntc_cC = 3000;
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_CLEAR_FAULTS), 0);
        th_advance(20000);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_IDLE);
        CHECK_EQ(th_reg_in(FW_REG_FAULT_BITS), 0);
    }
    SHOULD("fault LED_OPEN with the channel when the current sense reads almost nothing")
    {
        short_scan();
        th.led_fault[1] = 1;
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_START), 0);
        CHECK(th_run_until_state(FW_STATE_FAULT, 3000000));
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_LED_OPEN));
        CHECK_EQ(th_reg_in(FW_REG_FAULT_LOG_DETAIL(1)), 1);
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 1); /* light 0 was fine */
        CHECK_EQ(th.led_ch, -1);
    }
    SHOULD("fault LED_SHORT when the current sense reads far more than set")
    {
        short_scan();
        th.led_fault[0] = 2;
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_START), 0);
        CHECK(th_run_until_state(FW_STATE_FAULT, 3000000));
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_LED_SHORT));
    }
    SHOULD("cut a manual light after max_pulse_us and latch MAX_PULSE")
    {
        CHECK_EQ(th_write32(FW_REG_MAX_PULSE_US, 100000), 0);
        manual(4, 300);
        th_advance(99000);
        CHECK_EQ(th.led_ch, 4);
        th_advance(3000);
        CHECK_EQ(th.led_ch, -1);
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_MAX_PULSE));
        CHECK_EQ((int16_t)th_reg_hold(FW_REG_MANUAL_CHANNEL), -1);
        CHECK_EQ(th_write(FW_REG_MANUAL_CHANNEL, 4), 4); /* refused while latched */
    }
    SHOULD("not take an LED lit by an interrupt during the safety poll for an endless pulse")
    {
        th_advance(20000);
        th.adc_hook = light_mid_poll;
        th_advance(20000);
        CHECK(th.adc_hook == NULL);
        CHECK_EQ(th.led_ch, 6);
        CHECK_EQ(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_MAX_PULSE), 0);
    }
    SHOULD("switch a manual light off when the host is silent for host_watchdog_ms")
    {
        CHECK_EQ(th_write(FW_REG_HOST_WATCHDOG_MS, 200), 0);
        manual(5, 300);
        th_advance(150000);
        CHECK_EQ(th_reg_in(FW_REG_LED_CHANNEL), 5); /* this request feeds the watchdog */
        th_advance(199000);
        CHECK_EQ(th.led_ch, 5);
        th_advance(3000);
        CHECK_EQ(th.led_ch, -1);
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_HOST_SILENT));
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_IDLE); /* informational, not blocking */
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
    }
    SHOULD("keep a running scan going while the host is silent")
    {
        CHECK_EQ(th_write(FW_REG_HOST_WATCHDOG_MS, 100), 0);
        short_scan();
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_START), 0);
        unsigned kicks = th.wdt_kicks;
        CHECK(th_run_until_state(FW_STATE_DONE, 3000000));
        CHECK_EQ(regs_get(FW_SLOT_FRAMES_DONE), 2);
        CHECK(th.wdt_kicks > kicks + 100); /* hardware watchdog fed all along */
    }
    SHOULD("fault SUPPLY_LOW when the LED supply sags while lit")
    {
        manual(0, 300);
        th.supply_mV = 8000;
        th_advance(20000);
        CHECK_EQ(th.led_ch, -1);
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_SUPPLY_LOW));
        CHECK_EQ(th_reg_in(FW_REG_SUPPLY_MV), 8000);
    }
    SHOULD("latch WATCHDOG_RESET after a watchdog reset without blocking a scan")
    {
        th_boot(HAL_RESET_WATCHDOG);
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_WATCHDOG_RESET));
        CHECK_EQ(th_reg_in(FW_REG_RESET_CAUSE), FW_RESET_CAUSE_WATCHDOG);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
    }
}
