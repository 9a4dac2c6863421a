/*
 * board.h - pin map of the facette rig board (STM32F405RG, LQFP64).
 *
 *   USART1  PA9 TX, PA10 RX (AF7)        Modbus RTU, 115200 8N1
 *   DAC1    PA4                           current-sink setpoint, 0..3.3 V
 *   ADC1    PA0 IN0 current sense         shunt 0.1 ohm x gain 10: 1 mV per mA
 *           PA1 IN1 NTC divider           10 kohm pull-up to 3.3 V, NTC to ground
 *           PA2 IN2 supply divider        1/11 (100 k / 10 k): 36.3 V full scale
 *   GPIOB   PB0..PB15                     LED channel switches 0..15 (high = on)
 *   GPIOC   PC0 shutter, PC1 focus        opto-coupled camera remote (high = active)
 *           PC3 status LED (high = lit)
 *           PC2 flash-sync input, EXTI2   X-sync contact through an opto: rising = flash
 *           PC13 button, EXTI none        to 3.3 V with the internal pull-down
 *
 * Inputs are active-high on purpose: an unmodelled GPIO block (QEMU) reads 0,
 * which is then "button released, no sync", never a phantom press.
 * PB2 is BOOT1, sampled only at reset (pulled low on the board); after reset it
 * is an ordinary output.
 */
#ifndef BOARD_H
#define BOARD_H

#include "stm32f405_regs.h"

#define BOARD_LED_PORT      GPIOB_BASE
#define BOARD_LED_CHANNELS  16u

#define BOARD_CTRL_PORT     GPIOC_BASE
#define BOARD_PIN_SHUTTER   0u
#define BOARD_PIN_FOCUS     1u
#define BOARD_PIN_SYNC      2u
#define BOARD_PIN_STATUS    3u
#define BOARD_PIN_BUTTON    13u

#define BOARD_ADC_CH_CURRENT 0u
#define BOARD_ADC_CH_NTC     1u
#define BOARD_ADC_CH_SUPPLY  2u

/* Analog front end, for the conversions in hal_adc_read(). */
#define BOARD_VREF_MV        3300
#define BOARD_ADC_FULL       4095
#define BOARD_SENSE_MV_PER_MA 1          /* 0.1 ohm x 10 */
#define BOARD_SUPPLY_DIVIDER 11          /* (100 k + 10 k) / 10 k */
#define BOARD_NTC_R25_OHM    10000.0f
#define BOARD_NTC_BETA_K     3950.0f
#define BOARD_NTC_PULLUP_OHM 10000.0f

/* Wait for interrupts between main-loop polls (SysTick wakes the core every ms). */
#ifndef BOARD_IDLE_WFI
#define BOARD_IDLE_WFI       1
#endif

#endif /* BOARD_H */
