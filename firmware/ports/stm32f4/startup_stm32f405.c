/*
 * startup_stm32f405.c - vector table and reset handler of the STM32F405.
 *
 * The reset handler enables the FPU (the build uses -mfloat-abi=hard), copies
 * .data from flash, zeroes .bss, sets up the clocks and calls main().
 * Every interrupt without a handler goes to default_handler, which parks the
 * core so that the hardware watchdog resets it.
 */
#include <stdint.h>
#include <string.h>

#include "stm32f405_regs.h"

extern uint32_t __stack_top;
extern uint32_t __data_start, __data_end, __data_load;
extern uint32_t __bss_start, __bss_end;

int main(void);
void stm32_clock_init(void);
void Reset_Handler(void);

static void default_handler(void)
{
    for (;;) {
        /* An unexpected exception: wait for the watchdog. */
    }
}

#define WEAK_ALIAS __attribute__((weak, alias("default_handler")))
void NMI_Handler(void) WEAK_ALIAS;
void HardFault_Handler(void) WEAK_ALIAS;
void MemManage_Handler(void) WEAK_ALIAS;
void BusFault_Handler(void) WEAK_ALIAS;
void UsageFault_Handler(void) WEAK_ALIAS;
void SVC_Handler(void) WEAK_ALIAS;
void DebugMon_Handler(void) WEAK_ALIAS;
void PendSV_Handler(void) WEAK_ALIAS;
void SysTick_Handler(void) WEAK_ALIAS;
void EXTI2_IRQHandler(void) WEAK_ALIAS;
void USART1_IRQHandler(void) WEAK_ALIAS;
void EXTI15_10_IRQHandler(void) WEAK_ALIAS;
void TIM5_IRQHandler(void) WEAK_ALIAS;

typedef void (*vector_t)(void);

/* 16 core exceptions then the 82 STM32F405 interrupts (RM0090 table 61).
 * Every interrupt defaults to default_handler (a NULL vector would fault at
 * address 0 instead); the ones the port uses are then named. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Woverride-init"
__attribute__((section(".isr_vector"), used))
static const vector_t vector_table[16 + IRQ_COUNT] = {
    [16 ... 16 + IRQ_COUNT - 1] = default_handler,
    [0] = (vector_t)(uintptr_t)&__stack_top,
    [1] = Reset_Handler,
    [2] = NMI_Handler,
    [3] = HardFault_Handler,
    [4] = MemManage_Handler,
    [5] = BusFault_Handler,
    [6] = UsageFault_Handler,
    [11] = SVC_Handler,
    [12] = DebugMon_Handler,
    [14] = PendSV_Handler,
    [15] = SysTick_Handler,
    [16 + IRQ_EXTI2] = EXTI2_IRQHandler,
    [16 + IRQ_USART1] = USART1_IRQHandler,
    [16 + IRQ_EXTI15_10] = EXTI15_10_IRQHandler,
    [16 + IRQ_TIM5] = TIM5_IRQHandler,
};
#pragma GCC diagnostic pop

void Reset_Handler(void)
{
    /* CP10 and CP11 full access: the FPU must be on before any float code. */
    SCB_CPACR |= (0xFu << 20);
    __asm volatile("dsb\n isb" ::: "memory");

    uint32_t *src = &__data_load;
    for (uint32_t *dst = &__data_start; dst < &__data_end;) {
        *dst++ = *src++;
    }
    for (uint32_t *dst = &__bss_start; dst < &__bss_end;) {
        *dst++ = 0u;
    }

    SCB_VTOR = (uint32_t)(uintptr_t)vector_table;
    stm32_clock_init();
    (void)main();
    default_handler();
}
