/* led.h - constant-current LED sink: one channel at a time, DAC setpoint with
 * the channel's calibration gain, derating and the current limit (safe.h). */
#ifndef FACETTE_LED_H
#define FACETTE_LED_H

#include <stdint.h>

#include "fw_err.h"

void led_init(void);
/* Light channel ch at set_mA before gain; returns the sink current set (mA),
 * after gain, derating and the current limit (0: nothing lit). */
uint16_t led_on(int ch, uint16_t set_mA);
void led_off(void);
int led_channel(void);          /* channel in the sink, -1 none */
uint16_t led_sink_mA(void);     /* its sink current */
uint64_t led_on_since_us(void); /* when that channel was switched in */
/* set_mA times channel ch's calibration gain, rounded (ch < FW_CFG_MAX_LEDS);
 * before derating and limits. */
uint32_t led_gained_mA(unsigned ch, uint16_t set_mA);
/* Read the current sense while lit; FW_ERR_FAULT after latching LED_OPEN or
 * LED_SHORT when it disagrees with the setpoint. *meas_mA gets the reading. */
fw_err_t led_check(uint16_t *meas_mA);

#endif
