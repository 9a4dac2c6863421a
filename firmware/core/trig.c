/* trig.c - camera lines (shutter, focus), flash-sync capture, button debounce. */
#include "trig.h"

#include "fw_config.h"
#include "hal.h"

static bool s_btn_level, s_btn_raw;
static uint64_t s_btn_change;
static bool s_sync_pending;
static uint64_t s_sync_t;

void trig_init(void)
{
    hal_gpio_write(HAL_LINE_SHUTTER, false);
    hal_gpio_write(HAL_LINE_FOCUS, false);
    s_btn_raw = s_btn_level = hal_button_read();
    s_btn_change = hal_time_us();
    trig_sync_flush();
}

void trig_shutter(bool active) { hal_gpio_write(HAL_LINE_SHUTTER, active); }
void trig_focus(bool active) { hal_gpio_write(HAL_LINE_FOCUS, active); }

void trig_sync_flush(void)
{
    uint64_t t;
    while (hal_sync_take(&t)) {
    }
    s_sync_pending = false;
}

bool trig_sync_seen(uint64_t t_from, uint64_t *t_edge)
{
    uint64_t t;
    while (!s_sync_pending && hal_sync_take(&t)) {
        if (t >= t_from) { /* edges from before the release are stray: ignore */
            s_sync_pending = true;
            s_sync_t = t;
        }
    }
    if (s_sync_pending)
        *t_edge = s_sync_t;
    return s_sync_pending;
}

bool trig_button_pressed(void)
{
    uint64_t now = hal_time_us();
    bool raw = hal_button_read();
    if (raw != s_btn_raw) {
        s_btn_raw = raw;
        s_btn_change = now;
    }
    if (s_btn_raw != s_btn_level && now - s_btn_change >= FW_CFG_DEBOUNCE_US) {
        s_btn_level = s_btn_raw;
        return s_btn_level; /* a press is the debounced edge to "pressed" */
    }
    return false;
}
