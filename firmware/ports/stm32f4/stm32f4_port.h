/*
 * stm32f4_port.h - port-private interface between the STM32F405 drivers
 * (clock, µs clock, USART1) and the HAL implementation. Nothing above ports/
 * includes it.
 */
#ifndef STM32F4_PORT_H
#define STM32F4_PORT_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* HSE crystal of the rig board (Hz). When it does not start, the port runs the
 * PLL from the 16 MHz HSI instead: same 168 MHz, looser UART tolerance. */
#define STM32_HSE_HZ        8000000u
#define STM32_HSI_HZ        16000000u
#define STM32_SYSCLK_PLL_HZ 168000000u
/* QEMU's netduinoplus2 has no RCC model and clocks its core at a fixed 168 MHz. */
#define STM32_EMULATOR_HCLK_HZ 168000000u

/* Where the core clock comes from, decided once by stm32_clock_init(). */
typedef enum {
    STM32_CLK_HSI = 0,      /* PLL did not lock: 16 MHz internal RC */
    STM32_CLK_PLL_HSE,      /* normal: 168 MHz from the 8 MHz crystal */
    STM32_CLK_PLL_HSI,      /* crystal failed: 168 MHz from the RC */
    STM32_CLK_EMULATED,     /* no RCC present (QEMU): fixed 168 MHz */
} stm32_clk_source_t;

void stm32_clock_init(void);
stm32_clk_source_t stm32_clock_source(void);
uint32_t stm32_hclk_hz(void);
uint32_t stm32_pclk2_hz(void);
/* RCC_CSR as read at reset, before its flags were cleared (0 under QEMU). */
uint32_t stm32_reset_flags(void);

/* Monotonic µs since boot from SysTick (a Cortex-M core timer, so exact under
 * QEMU too). Safe from thread and interrupt context. */
uint64_t stm32_time_us(void);
/* Called from SysTick_Handler every millisecond, after the tick is counted. */
void stm32_tick_hook(void);

/* USART1, 8N1. Bytes received go to an interrupt-filled ring with the line
 * silence before each; writes go to an interrupt-drained ring. */
void stm32_uart_init(uint32_t baud);
/* Next byte (0..255) and the silence before it in µs, or -1 if none. */
int stm32_uart_getc(uint32_t *gap_us);
bool stm32_uart_rx_pending(void);
/* µs since the last byte ended (UINT32_MAX before the first byte). */
uint32_t stm32_uart_idle_us(void);
/* Queue up to len bytes; returns how many were queued (the ring may be full). */
size_t stm32_uart_write(const uint8_t *buf, size_t len);
bool stm32_uart_tx_idle(void);
/* Bytes lost because the ring was full or the USART overran. */
uint32_t stm32_uart_rx_dropped(void);

/* Main-loop wake-up: interrupts that may give fw_poll() work call
 * stm32_wake(); the main loop sleeps only when no wake-up is pending. */
void stm32_wake(void);

static inline uint32_t stm32_irq_save(void)
{
    uint32_t primask;
    __asm volatile("mrs %0, primask\n cpsid i" : "=r"(primask) :: "memory");
    return primask;
}

static inline void stm32_irq_restore(uint32_t primask)
{
    __asm volatile("msr primask, %0" :: "r"(primask) : "memory");
}

#endif /* STM32F4_PORT_H */
