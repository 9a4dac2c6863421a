/* fw.c - glue: start-up, main-loop poll, register side effects, commands.
 * The top of the core: it alone calls the other modules' functions, fills the
 * Modbus server's callbacks and registers the fault hook. */
#include "fw_config.h"
#include "fw_registers.h"
#include "hal.h"
#include "led.h"
#include "mb.h"
#include "nvm.h"
#include "regs.h"
#include "safe.h"
#include "seq.h"
#include "trig.h"

static bool s_reboot;
static bool s_unlocked;
static uint64_t s_unlock_until;
static nvm_cal_t s_cal;

static bool reboot_pending(void) { return s_reboot; }

static void set_lock(bool unlocked)
{
    s_unlocked = unlocked;
    s_unlock_until = hal_time_us() + FW_CFG_UNLOCK_TIMEOUT_US;
    regs_set(FW_SLOT_CAL_UNLOCK, unlocked ? 1u : 0u);
    regs_set(FW_SLOT_CAL_UNLOCKED, unlocked ? 1u : 0u);
}

static void cal_to_regs(void)
{
    for (unsigned i = 0; i < FW_CFG_MAX_LEDS; i++)
        regs_set(FW_SLOT_CAL_GAIN + i, s_cal.gain[i]);
    regs_set(FW_SLOT_CAL_SERIAL, s_cal.serial);
    regs_set(FW_SLOT_SERIAL_NUMBER, s_cal.serial ? s_cal.serial : hal_unique_id());
    regs_set(FW_SLOT_CAL_SEQUENCE, s_cal.seq);
}

/* The one fault hook (safe.h): what a latched fault does to the lights, the
 * camera lines and the sequencer. */
static void on_fault(safe_action_t action)
{
    if (action == SAFE_KEEP_GOING)
        return;
    led_off();
    if (action == SAFE_STOP) {
        trig_shutter(false);
        trig_focus(false);
    }
    regs_set(FW_SLOT_MANUAL_CHANNEL, (uint32_t)-1);
    if (action == SAFE_STOP)
        seq_on_fault();
}

static const safe_hooks_t k_safe_hooks = {
    .on_fault = on_fault,
    .lit_channel = led_channel,
    .lit_since_us = led_on_since_us,
    .scan_active = seq_active,
};

void fw_on_timer(void)
{
    seq_on_timer();
}

/* Bring the live input registers up to date (before a Modbus read). */
static void refresh_inputs(void)
{
    regs_set(FW_SLOT_UPTIME_S, (uint32_t)(hal_time_us() / 1000000u));
    regs_set(FW_SLOT_LED_CHANNEL, (uint32_t)led_channel());
    regs_set(FW_SLOT_LED_SET_MA, led_sink_mA());
    seq_update_status();
}

static void manual_apply(void)
{
    int ch = regs_get_i(FW_SLOT_MANUAL_CHANNEL);
    uint16_t mA = (uint16_t)regs_get(FW_SLOT_MANUAL_CURRENT_MA);
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

/* May value be written to slot now (state, lock)? */
static fw_err_t reg_check(unsigned slot, uint32_t value)
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
            s_cal.gain[i] = (uint16_t)regs_get(FW_SLOT_CAL_GAIN + i);
        s_cal.serial = regs_get(FW_SLOT_CAL_SERIAL);
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

/* Side effects of a stored write: commands, unlock, manual light. */
static fw_err_t reg_apply(unsigned slot, uint32_t value)
{
    if (slot == FW_SLOT_COMMAND) {
        regs_set(FW_SLOT_COMMAND, 0);
        return command(value);
    }
    if (slot == FW_SLOT_CAL_UNLOCK) {
        set_lock(value == FW_UNLOCK_KEY);
        return FW_OK;
    }
    /* a manual light follows its setpoint, its channel's gain and the current
     * limit at once (a lowered max_current_mA must not wait for the next write) */
    if (slot == FW_SLOT_MANUAL_CHANNEL || slot == FW_SLOT_MANUAL_CURRENT_MA ||
        ((slot_in(slot, FW_SLOT_CAL_GAIN, FW_CFG_MAX_LEDS) || slot == FW_SLOT_MAX_CURRENT_MA) &&
         led_channel() >= 0 && !seq_active()))
        manual_apply();
    return FW_OK;
}

static void request_failed(fw_err_t e)
{
    regs_set(FW_SLOT_LAST_ERROR, (uint32_t)(int32_t)e);
}

static const mb_callbacks_t k_mb_callbacks = {
    .refresh = refresh_inputs,
    .read = regs_get,
    .check = reg_check,
    .write = regs_set,
    .apply = reg_apply,
    .host_seen = safe_host_seen,
    .failed = request_failed,
    .stop = reboot_pending,
};

void fw_init(void)
{
    s_reboot = false;
    regs_init();
    regs_set(FW_SLOT_FW_VERSION, FW_CFG_FW_VERSION);
    regs_set(FW_SLOT_PROTOCOL_VERSION, FW_PROTOCOL_VERSION);
    regs_set(FW_SLOT_DEFINITION_HASH, FW_DEFINITION_HASH);
    uint32_t boots = hal_boot_count();
    regs_set(FW_SLOT_BOOT_COUNT, boots > 0xFFFFu ? 0xFFFFu : boots);
    regs_set(FW_SLOT_RESET_CAUSE, (uint32_t)hal_reset_cause());
    regs_set(FW_SLOT_MAX_LEDS, FW_CFG_MAX_LEDS);
    regs_set(FW_SLOT_RING_LEN, FW_CFG_RING_LEN);
    regs_set(FW_SLOT_LED_CHANNEL, (uint32_t)-1);
    led_init();
    trig_init();
    seq_init();
    safe_init(&k_safe_hooks);
    if (nvm_load(&s_cal) != FW_OK)
        safe_fault(FW_FAULT_CAL_INVALID, 0);
    cal_to_regs();
    set_lock(false);
    mb_init(&k_mb_callbacks);
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
            request_failed(e);
    }
    safe_poll();
    if (s_unlocked && hal_time_us() > s_unlock_until)
        set_lock(false);
    hal_gpio_write(HAL_LINE_STATUS, seq_active() || safe_blocking_fault());
}
