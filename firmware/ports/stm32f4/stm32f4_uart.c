/*
 * stm32f4_uart.c - USART1 on PA9 (TX) / PA10 (RX), AF7, 8N1, interrupt driven.
 *
 * The receive interrupt timestamps every byte on the µs clock and stores the
 * line silence before it next to it in the ring, so the Modbus layer frames
 * on the 3.5-character silence of the line, not on when it happens to poll
 * (QEMU's USART model delivers bytes as fast as DR is read, with no baud
 * timing: see stm32_uart_init). Transmission drains a ring so the core never waits on the
 * line: tx_pump() fills DR while TXE is set, from the writer and from the TXE
 * interrupt. On silicon TXE is set for about one byte at a time and the
 * interrupt does the rest; QEMU 7.2's USART never raises a TXE interrupt but
 * keeps TXE always set, so the writer's pump sends the whole frame at once.
 */
#include "stm32f4_port.h"
#include "stm32f405_regs.h"

#define RX_RING 512u    /* power of two; > one 256-byte Modbus frame */
#define TX_RING 256u    /* one answer; hal_uart_write() waits for room */

static uint8_t s_rx[RX_RING];
/* Silence before each byte in µs, saturated: UINT16_MAX (65 ms, far above any
 * framing time) stands for "long", reported as UINT32_MAX. */
static uint16_t s_rx_gap[RX_RING];
static volatile uint32_t s_rx_head, s_rx_tail;   /* head written by the ISR */
static uint32_t s_char_us;                        /* one 10-bit character */
static uint32_t s_burst_us;                       /* emulator: jitter inside a burst */
static volatile bool s_rx_seen;
static uint8_t s_tx[TX_RING];
static volatile uint32_t s_tx_head, s_tx_tail;   /* tail written by the ISR */
static volatile uint64_t s_last_rx_us;
static volatile uint32_t s_rx_dropped;

static void gpio_af7(uint32_t pin)
{
    GPIO_MODER(GPIOA_BASE) = (GPIO_MODER(GPIOA_BASE) & ~(3u << (2u * pin))) |
                             (GPIO_MODE_AF << (2u * pin));
    GPIO_OSPEEDR(GPIOA_BASE) |= 2u << (2u * pin);
    volatile uint32_t *afr = pin < 8u ? &GPIO_AFRL(GPIOA_BASE) : &GPIO_AFRH(GPIOA_BASE);
    uint32_t shift = 4u * (pin & 7u);
    *afr = (*afr & ~(0xFu << shift)) | (7u << shift);
}

void stm32_uart_init(uint32_t baud)
{
    RCC_AHB1ENR |= RCC_AHB1ENR_GPIOA;
    RCC_APB2ENR |= RCC_APB2ENR_USART1;
    (void)RCC_APB2ENR;  /* let the clock enable land before touching USART1 */
    gpio_af7(9u);
    gpio_af7(10u);
    GPIO_PUPDR(GPIOA_BASE) = (GPIO_PUPDR(GPIOA_BASE) & ~(3u << 20)) | (1u << 20); /* RX pull-up */

    USART_CR1(USART1_BASE) = 0u;
    USART_CR2(USART1_BASE) = 0u;   /* 1 stop bit */
    USART_CR3(USART1_BASE) = 0u;
    USART_BRR(USART1_BASE) = (stm32_pclk2_hz() + baud / 2u) / baud;  /* OVER8 = 0 */
    s_char_us = (10u * 1000000u + baud - 1u) / baud;
    /* QEMU's USART has no line timing: it hands over the next byte of a burst
     * when the guest has read the previous one and its I/O thread runs, which
     * on a loaded host can take more than 1.5 characters (0.75 ms at 115200).
     * Such a pause is scheduling jitter, not line silence, so under emulation
     * any pause shorter than the 3.5-character frame gap (1.75 ms above
     * 19200 bit/s) is reported as none. On silicon the measured gap stands. */
    s_burst_us = stm32_clock_source() == STM32_CLK_EMULATED ? 1750u : 0u;
    s_rx_head = s_rx_tail = 0u;
    s_tx_head = s_tx_tail = 0u;
    USART_CR1(USART1_BASE) = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;

    NVIC_IPR_BYTE(IRQ_USART1) = 0x80u;
    NVIC_ISER(IRQ_USART1 / 32u) = 1u << (IRQ_USART1 % 32u);
}

/* Call with interrupts masked or from the USART1 interrupt. */
static void tx_pump(void)
{
    uint32_t tail = s_tx_tail;
    while (tail != s_tx_head && (USART_SR(USART1_BASE) & USART_SR_TXE)) {
        USART_DR(USART1_BASE) = s_tx[tail % TX_RING];
        tail++;
    }
    s_tx_tail = tail;
    if (tail != s_tx_head) {
        USART_CR1(USART1_BASE) |= USART_CR1_TXEIE;
    } else {
        USART_CR1(USART1_BASE) &= ~USART_CR1_TXEIE;
    }
}

void USART1_IRQHandler(void)
{
    uint32_t sr = USART_SR(USART1_BASE);
    if (sr & (USART_SR_RXNE | USART_SR_ORE)) {
        /* Reading DR after SR clears RXNE and the error flags. */
        uint8_t byte = (uint8_t)USART_DR(USART1_BASE);
        uint64_t now = stm32_time_us();
        if (sr & USART_SR_ORE) {
            s_rx_dropped++;
        }
        /* RXNE rises at the end of a character: the silence before this byte
         * is the time since the previous one ended, less its own length. */
        uint32_t gap = UINT32_MAX;
        if (s_rx_seen) {
            uint64_t d = now - s_last_rx_us;
            gap = d > UINT32_MAX ? UINT32_MAX : (uint32_t)d;
            gap = gap > s_char_us ? gap - s_char_us : 0u;
            if (gap < s_burst_us) {
                gap = 0u;
            }
        }
        uint32_t head = s_rx_head;
        if (head - s_rx_tail < RX_RING) {
            s_rx[head % RX_RING] = byte;
            s_rx_gap[head % RX_RING] = gap >= UINT16_MAX ? UINT16_MAX : (uint16_t)gap;
            s_rx_head = head + 1u;
        } else {
            s_rx_dropped++;
        }
        s_last_rx_us = now;
        s_rx_seen = true;
        stm32_wake();
    }
    if (USART_CR1(USART1_BASE) & USART_CR1_TXEIE) {
        tx_pump();
    }
}

int stm32_uart_getc(uint32_t *gap_us)
{
    uint32_t tail = s_rx_tail;
    if (tail == s_rx_head) {
        return -1;
    }
    int byte = s_rx[tail % RX_RING];
    if (gap_us != NULL) {
        uint16_t gap = s_rx_gap[tail % RX_RING];
        *gap_us = gap == UINT16_MAX ? UINT32_MAX : gap;
    }
    s_rx_tail = tail + 1u;
    return byte;
}

bool stm32_uart_rx_pending(void)
{
    return s_rx_tail != s_rx_head;
}

uint32_t stm32_uart_idle_us(void)
{
    uint32_t pm = stm32_irq_save();
    bool seen = s_rx_seen;
    uint64_t last = s_last_rx_us;
    stm32_irq_restore(pm);
    if (!seen) {
        return UINT32_MAX;
    }
    uint64_t d = stm32_time_us() - last;
    return d > UINT32_MAX ? UINT32_MAX : (uint32_t)d;
}

size_t stm32_uart_write(const uint8_t *buf, size_t len)
{
    size_t n = 0;
    uint32_t head = s_tx_head;
    while (n < len && head - s_tx_tail < TX_RING) {
        s_tx[head % TX_RING] = buf[n++];
        head++;
    }
    s_tx_head = head;
    uint32_t pm = stm32_irq_save();
    tx_pump();
    stm32_irq_restore(pm);
    return n;
}

bool stm32_uart_tx_idle(void)
{
    return s_tx_head == s_tx_tail && (USART_SR(USART1_BASE) & USART_SR_TC);
}

uint32_t stm32_uart_rx_dropped(void) { return s_rx_dropped; }
