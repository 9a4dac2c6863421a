/* Bring-up only: echo every byte received on USART1. Replaced by the core. */
#include "stm32f4_port.h"

int main(void)
{
    stm32_uart_init(115200u);
    static const uint8_t hello[] = "facette stm32f4 echo\r\n";
    stm32_uart_write(hello, sizeof hello - 1u);
    for (;;) {
        uint8_t buf[64];
        size_t n = stm32_uart_read(buf, sizeof buf);
        if (n) {
            stm32_uart_write(buf, n);
        }
        __asm volatile("wfi");
    }
}
