/*
 * ports/template - a blank port that compiles: every HAL function with the
 * smallest body that satisfies its contract. Copy this directory to start a new
 * port and replace each body with the hardware's.
 */
#include "hal.h"

uint32_t hal_uart_baud(void) { return 115200u; }
int hal_uart_getc(uint32_t *gap_us) { (void)gap_us; return -1; }
uint32_t hal_uart_idle_us(void) { return UINT32_MAX; }
void hal_uart_write(const uint8_t *data, size_t len) { (void)data; (void)len; }

static uint64_t s_now_us;
uint64_t hal_time_us(void) { return s_now_us++; }
void hal_timer_start(uint64_t at_us) { (void)at_us; }
void hal_timer_cancel(void) {}

void hal_gpio_write(hal_line_t line, bool active) { (void)line; (void)active; }
void hal_led_select(int ch) { (void)ch; }
bool hal_button_read(void) { return false; }
bool hal_sync_take(uint64_t *t_us) { (void)t_us; return false; }
void hal_frame_annotate(const hal_frame_tag_t *tag) { (void)tag; }
void hal_dac_set(uint16_t code) { (void)code; }
int32_t hal_adc_read(hal_adc_t ch)
{
    switch (ch) {
    case HAL_ADC_NTC_CENTI_C: return 2500;
    case HAL_ADC_SUPPLY_MV: return 12000;
    default: return 0;
    }
}

uint32_t hal_flash_page_size(void) { return 1024u; }
int hal_flash_erase(unsigned page) { (void)page; return -1; }
int hal_flash_write(unsigned page, uint32_t offset, const void *data, size_t len)
{ (void)page; (void)offset; (void)data; (void)len; return -1; }
int hal_flash_read(unsigned page, uint32_t offset, void *data, size_t len)
{
    (void)page; (void)offset;
    for (size_t i = 0; i < len; i++)
        ((uint8_t *)data)[i] = 0xFFu;
    return 0;
}

hal_reset_cause_t hal_reset_cause(void) { return HAL_RESET_POWER_ON; }
uint32_t hal_boot_count(void) { return 1u; }
void hal_watchdog_kick(void) {}
void hal_critical_enter(void) {}
void hal_critical_exit(void) {}
void hal_reboot(void) {}
uint32_t hal_unique_id(void) { return 0u; }

int main(void)
{
    fw_init();
    for (;;)
        fw_poll();
}
