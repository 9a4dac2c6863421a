/*
 * stm32f4_clock.c - core clock and the µs clock of the STM32F405.
 *
 * 168 MHz from the PLL (8 MHz HSE / 8 * 336 / 2; 48 MHz on Q), APB1 42 MHz,
 * APB2 84 MHz, flash 5 wait states. Every wait on a ready bit is bounded: a
 * dead crystal falls back to the HSI, a PLL that does not lock leaves the chip
 * on the 16 MHz HSI, and the firmware still boots and talks.
 *
 * QEMU's netduinoplus2 does not model the RCC (it reads as zero). On silicon,
 * HSIRDY is always set when code runs (the chip boots on the HSI), so a zero
 * RCC_CR can only be an emulator: the port then takes QEMU's fixed 168 MHz
 * core clock. The same binary runs on both; no build flag is needed.
 *
 * The µs clock is SysTick on HCLK with a 1 ms period plus the current count.
 */
#include "stm32f4_port.h"
#include "stm32f405_regs.h"

#define READY_WAIT_LOOPS 200000u    /* > 10 ms at 16 MHz: HSE starts in ~2 ms */

static stm32_clk_source_t s_source = STM32_CLK_HSI;
static uint32_t s_hclk_hz = STM32_HSI_HZ;
static uint32_t s_pclk2_hz = STM32_HSI_HZ;
static uint32_t s_reset_flags;

static volatile uint64_t s_ms;
static uint32_t s_systick_reload;
static uint32_t s_cycles_per_us;

static bool wait_set(volatile uint32_t *reg, uint32_t mask, uint32_t value)
{
    for (uint32_t i = 0; i < READY_WAIT_LOOPS; i++) {
        if ((*reg & mask) == value) {
            return true;
        }
    }
    return false;
}

static void systick_start(void)
{
    s_cycles_per_us = s_hclk_hz / 1000000u;
    s_systick_reload = s_hclk_hz / 1000u - 1u;
    SYST_RVR = s_systick_reload;
    SYST_CVR = 0u;
    SCB_SHPR3 = (SCB_SHPR3 & 0x00FFFFFFu) | (0x40u << 24);  /* above USART */
    SYST_CSR = SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE;
}

void stm32_clock_init(void)
{
    s_reset_flags = RCC_CSR;
    RCC_CSR |= RCC_CSR_RMVF;

    if ((RCC_CR & RCC_CR_HSIRDY) == 0u) {
        s_source = STM32_CLK_EMULATED;
        s_hclk_hz = STM32_EMULATOR_HCLK_HZ;
        s_pclk2_hz = STM32_EMULATOR_HCLK_HZ / 2u;
        systick_start();
        return;
    }

    RCC_CR |= RCC_CR_HSEON;
    bool hse = wait_set(&RCC_CR, RCC_CR_HSERDY, RCC_CR_HSERDY);
    if (!hse) {
        RCC_CR &= ~RCC_CR_HSEON;
    }
    uint32_t pllm = hse ? STM32_HSE_HZ / 1000000u : STM32_HSI_HZ / 1000000u;

    RCC_APB1ENR |= RCC_APB1ENR_PWR;
    FLASH_ACR = FLASH_ACR_LATENCY_5WS | FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
    RCC_CFGR = RCC_CFGR_HPRE_DIV1 | RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
    /* VCO 336 MHz from 1 MHz input; P = 2 -> 168 MHz; Q = 7 -> 48 MHz. */
    RCC_PLLCFGR = pllm | (336u << 6) | (0u << 16) | (7u << 24) |
                  (hse ? RCC_PLLCFGR_SRC_HSE : 0u);
    RCC_CR |= RCC_CR_PLLON;
    if (wait_set(&RCC_CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY)) {
        RCC_CFGR |= RCC_CFGR_SW_PLL;
        if (wait_set(&RCC_CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_PLL)) {
            s_source = hse ? STM32_CLK_PLL_HSE : STM32_CLK_PLL_HSI;
            s_hclk_hz = STM32_SYSCLK_PLL_HZ;
        }
    }
    s_pclk2_hz = s_hclk_hz / 2u;
    systick_start();
}

stm32_clk_source_t stm32_clock_source(void) { return s_source; }
uint32_t stm32_hclk_hz(void) { return s_hclk_hz; }
uint32_t stm32_pclk2_hz(void) { return s_pclk2_hz; }
uint32_t stm32_reset_flags(void) { return s_reset_flags; }

__attribute__((weak)) void stm32_tick_hook(void) {}

void SysTick_Handler(void)
{
    s_ms++;
    stm32_tick_hook();
}

uint64_t stm32_time_us(void)
{
    uint32_t pm = stm32_irq_save();
    uint64_t ms = s_ms;
    uint32_t cvr = SYST_CVR;
    if (SCB_ICSR & SCB_ICSR_PENDSTSET) {
        /* The counter wrapped but the tick is not counted yet: count it and
         * re-read so that the sub-ms part belongs to the new period. */
        ms++;
        cvr = SYST_CVR;
    }
    stm32_irq_restore(pm);
    return ms * 1000u + (s_systick_reload - cvr) / s_cycles_per_us;
}
