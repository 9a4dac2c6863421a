/* fw.c - glue: start-up, main-loop poll, register side effects, commands. */
#include "fw_core.h"

static bool s_reboot;
static bool s_unlocked;
static uint64_t s_unlock_until;
static nvm_cal_t s_cal;

__attribute__((weak)) void fw_assert_failed(const char *file, int line)
{
    (void)file;
    (void)line;
    hal_critical_enter();
    hal_led_select(-1);
    hal_dac_set(0);
    for (;;) {
    }
}

bool fw_reboot_pending(void) { return s_reboot; }

static void set_lock(bool unlocked)
{
    s_unlocked = unlocked;
    s_unlock_until = hal_time_us() + FW_CFG_UNLOCK_TIMEOUT_US;
    mb_reg_set(FW_SLOT_CAL_UNLOCK, unlocked ? 1u : 0u);
    mb_reg_set(FW_SLOT_CAL_UNLOCKED, unlocked ? 1u : 0u);
}

static void cal_to_regs(void)
{
    for (unsigned i = 0; i < FW_CFG_MAX_LEDS; i++)
        mb_reg_set(FW_SLOT_CAL_GAIN + i, s_cal.gain[i]);
    mb_reg_set(FW_SLOT_CAL_SERIAL, s_cal.serial);
    mb_reg_set(FW_SLOT_SERIAL_NUMBER, s_cal.serial ? s_cal.serial : hal_unique_id());
    mb_reg_set(FW_SLOT_CAL_SEQUENCE, s_cal.seq);
}

void fw_init(void)
{
    s_reboot = false;
    mb_reg_init();
    mb_reg_set(FW_SLOT_FW_VERSION, FW_CFG_FW_VERSION);
    mb_reg_set(FW_SLOT_PROTOCOL_VERSION, FW_PROTOCOL_VERSION);
    mb_reg_set(FW_SLOT_DEFINITION_HASH, FW_DEFINITION_HASH);
    uint32_t boots = hal_boot_count();
    mb_reg_set(FW_SLOT_BOOT_COUNT, boots > 0xFFFFu ? 0xFFFFu : boots);
    mb_reg_set(FW_SLOT_RESET_CAUSE, (uint32_t)hal_reset_cause());
    mb_reg_set(FW_SLOT_MAX_LEDS, FW_CFG_MAX_LEDS);
    mb_reg_set(FW_SLOT_RING_LEN, FW_CFG_RING_LEN);
    mb_reg_set(FW_SLOT_LED_CHANNEL, (uint32_t)-1);
    led_init();
    trig_init();
    seq_init();
    safe_init();
    if (nvm_load(&s_cal) != FW_OK)
        safe_fault(FW_FAULT_CAL_INVALID, 0);
    cal_to_regs();
    set_lock(false);
    mb_init();
}

void fw_on_timer(void)
{
    seq_on_timer();
}

void fw_refresh_inputs(void)
{
    mb_reg_set(FW_SLOT_UPTIME_S, (uint32_t)(hal_time_us() / 1000000u));
    mb_reg_set(FW_SLOT_LED_CHANNEL, (uint32_t)led_channel());
    mb_reg_set(FW_SLOT_LED_SET_MA, led_sink_mA());
    seq_update_status();
}

static void manual_apply(void)
{
    int ch = mb_reg_get_i(FW_SLOT_MANUAL_CHANNEL);
    uint16_t mA = (uint16_t)mb_reg_get(FW_SLOT_MANUAL_CURRENT_MA);
    if (ch >= 0 && mA > 0)
        led_on(ch, mA);
    else
        led_off();
}

static bool slot_in(unsigned slot, unsigned first, unsigned count)
{
    return slot >= first && slot < first + count;
}

static bool is_scan_config(unsigned slot)
{
    return slot_in(slot, FW_SLOT_N_LIGHTS, FW_SLOT_EXPOSURE_CURRENT_MA + FW_CFG_MAX_EXPOSURES -
                                               FW_SLOT_N_LIGHTS) ||
           slot_in(slot, FW_SLOT_MAX_CURRENT_MA, FW_SLOT_MAX_PULSE_US + 1u - FW_SLOT_MAX_CURRENT_MA);
}

fw_err_t fw_reg_check(unsigned slot, uint32_t value)
{
    if (slot == FW_SLOT_COMMAND) {
        switch (value) {
        case FW_COMMAND_NONE:
        case FW_COMMAND_REBOOT:
            return FW_OK;
        case FW_COMMAND_SAVE:
            FW_VERIFY(s_unlocked, FW_ERR_LOCKED);
            FW_VERIFY(!seq_active(), FW_ERR_STATE);
            return FW_OK;
        default:
            return seq_command_check(value);
        }
    }
    if (is_scan_config(slot))
        FW_VERIFY(!seq_active(), FW_ERR_STATE);
    if (slot == FW_SLOT_MANUAL_CHANNEL || slot == FW_SLOT_MANUAL_CURRENT_MA) {
        FW_VERIFY(!seq_active(), FW_ERR_STATE);
        if (slot == FW_SLOT_MANUAL_CHANNEL && (int32_t)value >= 0)
            FW_VERIFY(!safe_blocking_fault(), FW_ERR_FAULT);
    }
    if (slot == FW_SLOT_CAL_SERIAL || slot_in(slot, FW_SLOT_CAL_GAIN, FW_CFG_MAX_LEDS)) {
        FW_VERIFY(s_unlocked, FW_ERR_LOCKED);
        FW_VERIFY(!seq_active(), FW_ERR_STATE);
    }
    return FW_OK;
}

static fw_err_t command(unsigned cmd)
{
    switch (cmd) {
    case FW_COMMAND_NONE:
        return FW_OK;
    case FW_COMMAND_REBOOT:
        s_reboot = true; /* after the answer has been sent */
        return FW_OK;
    case FW_COMMAND_SAVE: {
        for (unsigned i = 0; i < FW_CFG_MAX_LEDS; i++)
            s_cal.gain[i] = (uint16_t)mb_reg_get(FW_SLOT_CAL_GAIN + i);
        s_cal.serial = mb_reg_get(FW_SLOT_CAL_SERIAL);
        fw_err_t e = nvm_save(&s_cal);
        set_lock(false);
        cal_to_regs();
        return e;
    }
    case FW_COMMAND_CLEAR_FAULTS:
        safe_clear();
        return seq_command(cmd);
    default:
        return seq_command(cmd);
    }
}

fw_err_t fw_reg_apply(unsigned slot, uint32_t value)
{
    if (slot == FW_SLOT_COMMAND) {
        mb_reg_set(FW_SLOT_COMMAND, 0);
        return command(value);
    }
    if (slot == FW_SLOT_CAL_UNLOCK) {
        set_lock(value == FW_UNLOCK_KEY);
        return FW_OK;
    }
    if (slot == FW_SLOT_MANUAL_CHANNEL || slot == FW_SLOT_MANUAL_CURRENT_MA ||
        (slot_in(slot, FW_SLOT_CAL_GAIN, FW_CFG_MAX_LEDS) && led_channel() >= 0 && !seq_active()))
        manual_apply();
    return FW_OK;
}

void fw_poll(void)
{
    mb_poll();
    if (s_reboot) {
        hal_reboot();
        return;
    }
    if (trig_button_pressed()) {
        fw_err_t e = FW_OK;
        if (seq_active()) {
            e = seq_command(FW_COMMAND_ABORT);
        } else {
            e = seq_command(FW_COMMAND_ARM);
            if (e == FW_OK)
                e = seq_command(FW_COMMAND_START);
        }
        if (e != FW_OK)
            mb_reg_set(FW_SLOT_LAST_ERROR, (uint32_t)(int32_t)e);
    }
    safe_poll();
    if (s_unlocked && hal_time_us() > s_unlock_until)
        set_lock(false);
    hal_gpio_write(HAL_LINE_STATUS, seq_active() || safe_blocking_fault());
}
