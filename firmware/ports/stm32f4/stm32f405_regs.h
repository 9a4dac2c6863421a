/*
 * stm32f405_regs.h - the few STM32F405 / Cortex-M4 registers this port uses.
 *
 * Written by hand from RM0090 (STM32F405 reference manual) and the ARMv7-M
 * architecture manual, so that the port needs no vendor HAL or CMSIS download.
 * Port-private: nothing above ports/ may include it.
 */
#ifndef STM32F405_REGS_H
#define STM32F405_REGS_H

#include <stdint.h>

#define REG32(addr) (*(volatile uint32_t *)(uintptr_t)(addr))

/* ---- Cortex-M4 core ---------------------------------------------------- */
#define SCB_ICSR        REG32(0xE000ED04u)
#define SCB_ICSR_PENDSTSET (1u << 26)
#define SCB_VTOR        REG32(0xE000ED08u)
#define SCB_AIRCR       REG32(0xE000ED0Cu)
#define SCB_AIRCR_SYSRESETREQ (0x05FA0000u | (1u << 2))
#define SCB_SHPR3       REG32(0xE000ED20u)  /* PendSV, SysTick priority */
#define SCB_CPACR       REG32(0xE000ED88u)

#define SYST_CSR        REG32(0xE000E010u)
#define SYST_RVR        REG32(0xE000E014u)
#define SYST_CVR        REG32(0xE000E018u)
#define SYST_CSR_ENABLE    (1u << 0)
#define SYST_CSR_TICKINT   (1u << 1)
#define SYST_CSR_CLKSOURCE (1u << 2)        /* 1: processor clock (HCLK) */

#define NVIC_ISER(n)    REG32(0xE000E100u + 4u * (n))
#define NVIC_ICER(n)    REG32(0xE000E180u + 4u * (n))
#define NVIC_IPR_BYTE(irq) (*(volatile uint8_t *)(uintptr_t)(0xE000E400u + (irq)))

/* ---- IRQ numbers (RM0090 table 61) ------------------------------------- */
#define IRQ_EXTI2       8
#define IRQ_USART1      37
#define IRQ_EXTI15_10   40
#define IRQ_TIM5        50
#define IRQ_COUNT       82

/* ---- RCC (0x4002 3800) -------------------------------------------------- */
#define RCC_BASE        0x40023800u
#define RCC_CR          REG32(RCC_BASE + 0x00u)
#define RCC_PLLCFGR     REG32(RCC_BASE + 0x04u)
#define RCC_CFGR        REG32(RCC_BASE + 0x08u)
#define RCC_AHB1ENR     REG32(RCC_BASE + 0x30u)
#define RCC_APB1ENR     REG32(RCC_BASE + 0x40u)
#define RCC_APB2ENR     REG32(RCC_BASE + 0x44u)
#define RCC_CSR         REG32(RCC_BASE + 0x74u)

#define RCC_CR_HSION    (1u << 0)
#define RCC_CR_HSIRDY   (1u << 1)
#define RCC_CR_HSEON    (1u << 16)
#define RCC_CR_HSERDY   (1u << 17)
#define RCC_CR_PLLON    (1u << 24)
#define RCC_CR_PLLRDY   (1u << 25)
#define RCC_PLLCFGR_SRC_HSE (1u << 22)
#define RCC_CFGR_SW_PLL     2u
#define RCC_CFGR_SWS_MASK   (3u << 2)
#define RCC_CFGR_SWS_PLL    (2u << 2)
#define RCC_CFGR_HPRE_DIV1  (0u << 4)
#define RCC_CFGR_PPRE1_DIV4 (5u << 10)
#define RCC_CFGR_PPRE2_DIV2 (4u << 13)

#define RCC_AHB1ENR_GPIOA (1u << 0)
#define RCC_AHB1ENR_GPIOB (1u << 1)
#define RCC_AHB1ENR_GPIOC (1u << 2)
#define RCC_APB1ENR_TIM5  (1u << 3)
#define RCC_APB1ENR_PWR   (1u << 28)
#define RCC_APB1ENR_DAC   (1u << 29)
#define RCC_APB2ENR_USART1 (1u << 4)
#define RCC_APB2ENR_ADC1  (1u << 8)
#define RCC_APB2ENR_SYSCFG (1u << 14)

/* RCC_CSR reset flags (RM0090 §7.3.21) and RMVF to clear them */
#define RCC_CSR_RMVF     (1u << 24)
#define RCC_CSR_BORRSTF  (1u << 25)
#define RCC_CSR_PINRSTF  (1u << 26)
#define RCC_CSR_PORRSTF  (1u << 27)
#define RCC_CSR_SFTRSTF  (1u << 28)
#define RCC_CSR_IWDGRSTF (1u << 29)
#define RCC_CSR_WWDGRSTF (1u << 30)
#define RCC_CSR_LPWRRSTF (1u << 31)

/* ---- Flash interface (0x4002 3C00) ------------------------------------- */
#define FLASH_IF_BASE   0x40023C00u
#define FLASH_ACR       REG32(FLASH_IF_BASE + 0x00u)
#define FLASH_KEYR      REG32(FLASH_IF_BASE + 0x04u)
#define FLASH_SR        REG32(FLASH_IF_BASE + 0x0Cu)
#define FLASH_CR        REG32(FLASH_IF_BASE + 0x10u)
#define FLASH_ACR_LATENCY_5WS (5u << 0)
#define FLASH_ACR_PRFTEN (1u << 8)
#define FLASH_ACR_ICEN   (1u << 9)
#define FLASH_ACR_DCEN   (1u << 10)
#define FLASH_KEY1      0x45670123u
#define FLASH_KEY2      0xCDEF89ABu
#define FLASH_SR_BSY    (1u << 16)
#define FLASH_SR_ERRORS (0xF2u)             /* PGSERR PGPERR PGAERR WRPERR OPERR */
#define FLASH_CR_PG     (1u << 0)
#define FLASH_CR_SER    (1u << 1)
#define FLASH_CR_SNB(n) ((uint32_t)(n) << 3)
#define FLASH_CR_PSIZE_X32 (2u << 8)
#define FLASH_CR_STRT   (1u << 16)
#define FLASH_CR_LOCK   (1u << 31)

/* ---- GPIO ---------------------------------------------------------------- */
#define GPIOA_BASE      0x40020000u
#define GPIOB_BASE      0x40020400u
#define GPIOC_BASE      0x40020800u
#define GPIO_MODER(b)   REG32((b) + 0x00u)
#define GPIO_OTYPER(b)  REG32((b) + 0x04u)
#define GPIO_OSPEEDR(b) REG32((b) + 0x08u)
#define GPIO_PUPDR(b)   REG32((b) + 0x0Cu)
#define GPIO_IDR(b)     REG32((b) + 0x10u)
#define GPIO_ODR(b)     REG32((b) + 0x14u)
#define GPIO_BSRR(b)    REG32((b) + 0x18u)
#define GPIO_AFRL(b)    REG32((b) + 0x20u)
#define GPIO_AFRH(b)    REG32((b) + 0x24u)
#define GPIO_MODE_IN    0u
#define GPIO_MODE_OUT   1u
#define GPIO_MODE_AF    2u
#define GPIO_MODE_ANALOG 3u

/* ---- USART1 (APB2, 0x4001 1000) ---------------------------------------- */
#define USART1_BASE     0x40011000u
#define USART_SR(b)     REG32((b) + 0x00u)
#define USART_DR(b)     REG32((b) + 0x04u)
#define USART_BRR(b)    REG32((b) + 0x08u)
#define USART_CR1(b)    REG32((b) + 0x0Cu)
#define USART_CR2(b)    REG32((b) + 0x10u)
#define USART_CR3(b)    REG32((b) + 0x14u)
#define USART_SR_PE     (1u << 0)
#define USART_SR_FE     (1u << 1)
#define USART_SR_NF     (1u << 2)
#define USART_SR_ORE    (1u << 3)
#define USART_SR_RXNE   (1u << 5)
#define USART_SR_TC     (1u << 6)
#define USART_SR_TXE    (1u << 7)
#define USART_CR1_RE    (1u << 2)
#define USART_CR1_TE    (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_UE    (1u << 13)

/* ---- SYSCFG / EXTI ------------------------------------------------------- */
#define SYSCFG_BASE     0x40013800u
#define SYSCFG_EXTICR(n) REG32(SYSCFG_BASE + 0x08u + 4u * (n))
#define EXTI_BASE       0x40013C00u
#define EXTI_IMR        REG32(EXTI_BASE + 0x00u)
#define EXTI_RTSR       REG32(EXTI_BASE + 0x08u)
#define EXTI_FTSR       REG32(EXTI_BASE + 0x0Cu)
#define EXTI_PR         REG32(EXTI_BASE + 0x14u)

/* ---- ADC1 (0x4001 2000) -------------------------------------------------- */
#define ADC1_BASE       0x40012000u
#define ADC_SR(b)       REG32((b) + 0x00u)
#define ADC_CR1(b)      REG32((b) + 0x04u)
#define ADC_CR2(b)      REG32((b) + 0x08u)
#define ADC_SMPR2(b)    REG32((b) + 0x10u)
#define ADC_SQR1(b)     REG32((b) + 0x2Cu)
#define ADC_SQR3(b)     REG32((b) + 0x34u)
#define ADC_DR(b)       REG32((b) + 0x4Cu)
#define ADC_CCR         REG32(0x40012304u)
#define ADC_SR_EOC      (1u << 1)
#define ADC_CR2_ADON    (1u << 0)
#define ADC_CR2_SWSTART (1u << 30)
#define ADC_CCR_ADCPRE_DIV4 (1u << 16)

/* ---- DAC (0x4000 7400) --------------------------------------------------- */
#define DAC_BASE        0x40007400u
#define DAC_CR          REG32(DAC_BASE + 0x00u)
#define DAC_DHR12R1     REG32(DAC_BASE + 0x08u)
#define DAC_DOR1        REG32(DAC_BASE + 0x2Cu)
#define DAC_CR_EN1      (1u << 0)

/* ---- TIM5 (32-bit, APB1, 0x4000 0C00) ---------------------------------- */
#define TIM5_BASE       0x40000C00u
#define TIM_CR1(b)      REG32((b) + 0x00u)
#define TIM_DIER(b)     REG32((b) + 0x0Cu)
#define TIM_SR(b)       REG32((b) + 0x10u)
#define TIM_EGR(b)      REG32((b) + 0x14u)
#define TIM_CNT(b)      REG32((b) + 0x24u)
#define TIM_PSC(b)      REG32((b) + 0x28u)
#define TIM_ARR(b)      REG32((b) + 0x2Cu)
#define TIM_CCR1(b)     REG32((b) + 0x34u)
#define TIM_CR1_CEN     (1u << 0)
#define TIM_DIER_CC1IE  (1u << 1)
#define TIM_SR_CC1IF    (1u << 1)
#define TIM_EGR_UG      (1u << 0)

/* ---- IWDG (0x4000 3000) -------------------------------------------------- */
#define IWDG_BASE       0x40003000u
#define IWDG_KR         REG32(IWDG_BASE + 0x00u)
#define IWDG_PR         REG32(IWDG_BASE + 0x04u)
#define IWDG_RLR        REG32(IWDG_BASE + 0x08u)
#define IWDG_SR         REG32(IWDG_BASE + 0x0Cu)
#define IWDG_KEY_RELOAD 0xAAAAu
#define IWDG_KEY_UNLOCK 0x5555u
#define IWDG_KEY_START  0xCCCCu

/* ---- Unique device ID (96 bits, RM0090 §39.1) ---------------------------- */
#define UID_BASE        0x1FFF7A10u

#endif /* STM32F405_REGS_H */
