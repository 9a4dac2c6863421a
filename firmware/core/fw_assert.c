/* fw_assert.c - what a failed FW_ASSERT does unless the port says otherwise:
 * lights off and halt (ports override it to report file and line). */
#include "fw_err.h"
#include "hal.h"

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
