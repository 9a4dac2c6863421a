/*
 * hal_stm32f4.c - the facette HAL (hal/hal.h) on the STM32F405 rig board.
 *
 * Registers by hand (stm32f405_regs.h), pins in board.h. Every wait on a
 * hardware flag is bounded so that a missing or unmodelled peripheral costs a
 * failed operation, never a hang.
 *
 * Under QEMU (netduinoplus2), detected at reset by the absent RCC (see
 * stm32f4_clock.c), what the emulator lacks is handled as follows:
 *   - GPIO: not modelled; writes are lost, inputs read 0 (= idle, see board.h);
 *   - ADC: conversions never complete (EOC stays 0) and there is no analog
 *     front end, so hal_adc_read() returns the readings of a healthy idle rig
 *     (current = the setpoint of the selected LED, 25.00 degC, 12 V);
 *   - DAC, IWDG, flash controller: not modelled; writes are lost, the flash is
 *     a ROM, so erase/program fail their read-back and return an error;
 *   - TIM5 compare interrupts are not modelled: the SysTick interrupt (1 ms)
 *     also checks the one-shot deadline, so timers fire late but do fire;
 *   - the unique id (0x1FFF7A10) is unmapped: a fixed id is reported.
 */
#include <math.h>
#include <string.h>

#include "board.h"
#include "fw_config.h"
#include "hal.h"
#include "stm32f405_regs.h"
#include "stm32f4_port.h"

#define ADC_WAIT_LOOPS    10000u      /* one conversion takes ~5 us */
#define FLASH_WAIT_LOOPS  100000000u  /* > 1 s: a 16 KiB sector erases in 0.5 s max */
#define IWDG_WAIT_LOOPS   100000u
#define SYNC_RING         8u
#define EMULATED_UID      0x454D5531u /* "EMU1" */

/* Backup-domain registers keeping the boot counter across resets. */
#define PWR_CR            REG32(0x40007000u)
#define PWR_CR_DBP        (1u << 8)
#define RTC_BKP0R         REG32(0x40002850u)
#define RTC_BKP1R         REG32(0x40002854u)
#define BOOT_MAGIC        0xFACE77E0u

#define FLASH_ACR_ICRST   (1u << 11)
#define FLASH_ACR_DCRST   (1u << 12)
#define NVIC_ISPR(n)      REG32(0xE000E200u + 4u * (n))

extern uint8_t __nvm_page0[], __nvm_page1[], __nvm_page_size[];

static bool s_emulated;
static uint32_t s_boot_count;
static hal_reset_cause_t s_reset_cause;
static uint32_t s_crit_depth;
static uint32_t s_crit_primask;
static bool s_wdt_started;
static int s_led_channel = -1;
static uint32_t s_lines_known, s_lines_level;   /* shadow of the hal_line_t outputs */
static uint16_t s_dac_code;

/* One-shot timer: deadline checked by TIM5 compare (µs-precise on silicon)
 * and by SysTick every ms (the only one that fires under QEMU). */
static volatile bool s_timer_armed;
static volatile uint64_t s_timer_at_us;

/* Flash-sync edges timestamped by EXTI2. */
static volatile uint64_t s_sync_t[SYNC_RING];
static volatile uint32_t s_sync_head, s_sync_tail;

static volatile bool s_wake;

void stm32_wake(void)
{
    s_wake = true;
}

/* ---------------------------------------------------------------- helpers */

static void gpio_mode(uint32_t port, uint32_t pin, uint32_t mode)
{
    GPIO_MODER(port) = (GPIO_MODER(port) & ~(3u << (2u * pin))) | (mode << (2u * pin));
}

static void gpio_pull_down(uint32_t port, uint32_t pin)
{
    GPIO_PUPDR(port) = (GPIO_PUPDR(port) & ~(3u << (2u * pin))) | (2u << (2u * pin));
}

static void nvic_enable(uint32_t irq, uint8_t priority)
{
    NVIC_IPR_BYTE(irq) = priority;
    NVIC_ISER(irq / 32u) = 1u << (irq % 32u);
}

static hal_reset_cause_t reset_cause_from(uint32_t csr)
{
    if (csr & (RCC_CSR_IWDGRSTF | RCC_CSR_WWDGRSTF)) return HAL_RESET_WATCHDOG;
    if (csr & RCC_CSR_SFTRSTF) return HAL_RESET_SOFTWARE;
    if (csr & RCC_CSR_PORRSTF) return HAL_RESET_POWER_ON; /* POR also sets PIN and BOR */
    if (csr & RCC_CSR_BORRSTF) return HAL_RESET_BROWNOUT;
    if (csr & RCC_CSR_PINRSTF) return HAL_RESET_PIN;
    return HAL_RESET_UNKNOWN;
}

static void boot_count_update(void)
{
    RCC_APB1ENR |= RCC_APB1ENR_PWR;
    (void)RCC_APB1ENR;
    PWR_CR |= PWR_CR_DBP;
    if (RTC_BKP0R != BOOT_MAGIC) {          /* backup domain lost power */
        RTC_BKP0R = BOOT_MAGIC;
        RTC_BKP1R = 0u;
    }
    RTC_BKP1R = RTC_BKP1R + 1u;
    s_boot_count = RTC_BKP1R;
    if (s_boot_count == 0u) {
        s_boot_count = 1u;                  /* no backup domain (QEMU): this start */
    }
}

static void timer_init(void)
{
    /* TIM5: 32-bit, free-running at 1 MHz (APB1 timer clock = 2 x PCLK1 = HCLK / 2). */
    RCC_APB1ENR |= RCC_APB1ENR_TIM5;
    (void)RCC_APB1ENR;
    TIM_PSC(TIM5_BASE) = stm32_hclk_hz() / 2u / 1000000u - 1u;
    TIM_ARR(TIM5_BASE) = 0xFFFFFFFFu;
    TIM_EGR(TIM5_BASE) = TIM_EGR_UG;        /* load the prescaler */
    TIM_SR(TIM5_BASE) = 0u;
    TIM_CR1(TIM5_BASE) = TIM_CR1_CEN;
    nvic_enable(IRQ_TIM5, 0x40u);
}

static void board_init(void)
{
    s_emulated = stm32_clock_source() == STM32_CLK_EMULATED;
    s_reset_cause = reset_cause_from(stm32_reset_flags());
    boot_count_update();

    RCC_AHB1ENR |= RCC_AHB1ENR_GPIOA | RCC_AHB1ENR_GPIOB | RCC_AHB1ENR_GPIOC;
    RCC_APB1ENR |= RCC_APB1ENR_DAC;
    RCC_APB2ENR |= RCC_APB2ENR_ADC1 | RCC_APB2ENR_SYSCFG;
    (void)RCC_APB2ENR;

    /* LED switches: all off, then outputs. */
    GPIO_BSRR(BOARD_LED_PORT) = 0xFFFFu << 16;
    GPIO_MODER(BOARD_LED_PORT) = 0x55555555u;

    /* Camera lines and status LED: inactive, outputs. Button, sync: inputs. */
    GPIO_BSRR(BOARD_CTRL_PORT) = ((1u << BOARD_PIN_SHUTTER) | (1u << BOARD_PIN_FOCUS) |
                                  (1u << BOARD_PIN_STATUS)) << 16;
    gpio_mode(BOARD_CTRL_PORT, BOARD_PIN_SHUTTER, GPIO_MODE_OUT);
    gpio_mode(BOARD_CTRL_PORT, BOARD_PIN_FOCUS, GPIO_MODE_OUT);
    gpio_mode(BOARD_CTRL_PORT, BOARD_PIN_STATUS, GPIO_MODE_OUT);
    gpio_mode(BOARD_CTRL_PORT, BOARD_PIN_SYNC, GPIO_MODE_IN);
    gpio_pull_down(BOARD_CTRL_PORT, BOARD_PIN_SYNC);
    gpio_mode(BOARD_CTRL_PORT, BOARD_PIN_BUTTON, GPIO_MODE_IN);
    gpio_pull_down(BOARD_CTRL_PORT, BOARD_PIN_BUTTON);

    /* Flash sync: EXTI2 from port C, rising edge, highest priority so the
     * timestamp is taken promptly. */
    SYSCFG_EXTICR(0) = (SYSCFG_EXTICR(0) & ~(0xFu << 8)) | (2u << 8);
    EXTI_RTSR |= 1u << BOARD_PIN_SYNC;
    EXTI_FTSR &= ~(1u << BOARD_PIN_SYNC);
    EXTI_PR = 1u << BOARD_PIN_SYNC;
    EXTI_IMR |= 1u << BOARD_PIN_SYNC;
    nvic_enable(IRQ_EXTI2, 0x20u);

    /* DAC channel 1 on PA4 (output buffer on), starting at 0 mA. */
    gpio_mode(GPIOA_BASE, 4u, GPIO_MODE_ANALOG);
    DAC_DHR12R1 = 0u;
    DAC_CR = DAC_CR_EN1;

    /* ADC1: PA0..PA2 analog, 12-bit, single software-started conversions,
     * 84-cycle sampling (high-impedance NTC divider), ADC clock PCLK2 / 4. */
    gpio_mode(GPIOA_BASE, BOARD_ADC_CH_CURRENT, GPIO_MODE_ANALOG);
    gpio_mode(GPIOA_BASE, BOARD_ADC_CH_NTC, GPIO_MODE_ANALOG);
    gpio_mode(GPIOA_BASE, BOARD_ADC_CH_SUPPLY, GPIO_MODE_ANALOG);
    ADC_CCR = ADC_CCR_ADCPRE_DIV4;
    ADC_CR1(ADC1_BASE) = 0u;
    ADC_SMPR2(ADC1_BASE) = (4u << 0) | (4u << 3) | (4u << 6);
    ADC_SQR1(ADC1_BASE) = 0u;               /* one conversion per sequence */
    ADC_CR2(ADC1_BASE) = ADC_CR2_ADON;

    timer_init();
    stm32_uart_init(hal_uart_baud());
}

/* ------------------------------------------------------------------- UART */

uint32_t hal_uart_baud(void) { return 115200u; }

int hal_uart_getc(uint32_t *gap_us)
{
    return stm32_uart_getc(gap_us);
}

uint32_t hal_uart_idle_us(void)
{
    return stm32_uart_idle_us();
}

void hal_uart_write(const uint8_t *data, size_t len)
{
    while (len > 0u) {
        size_t n = stm32_uart_write(data, len);
        data += n;
        len -= n;
    }
}

/* ------------------------------------------------------- clock and timer */

uint64_t hal_time_us(void) { return stm32_time_us(); }

static void timer_fire_if_due(void)
{
    if (s_timer_armed && stm32_time_us() >= s_timer_at_us) {
        s_timer_armed = false;
        TIM_DIER(TIM5_BASE) &= ~TIM_DIER_CC1IE;
        fw_on_timer();
        stm32_wake();
    }
}

/* Program TIM5's compare for the current deadline; a deadline already due (or
 * within a µs) pends the interrupt at once. */
static void timer_program(void)
{
    uint64_t now = stm32_time_us();
    if (s_timer_at_us <= now + 1u) {
        NVIC_ISPR(IRQ_TIM5 / 32u) = 1u << (IRQ_TIM5 % 32u);
        return;
    }
    uint64_t delta = s_timer_at_us - now;
    if (delta > 0x7FFFFFFFu) {
        delta = 0x7FFFFFFFu;                /* > 35 min: re-armed on expiry */
    }
    uint32_t ccr = TIM_CNT(TIM5_BASE) + (uint32_t)delta;
    TIM_CCR1(TIM5_BASE) = ccr;
    TIM_SR(TIM5_BASE) = ~TIM_SR_CC1IF;
    TIM_DIER(TIM5_BASE) |= TIM_DIER_CC1IE;
    if ((int32_t)(ccr - TIM_CNT(TIM5_BASE)) <= 0) {
        /* The counter passed the compare value while it was being written: the
         * match would come a whole wrap later, so take the interrupt now. */
        NVIC_ISPR(IRQ_TIM5 / 32u) = 1u << (IRQ_TIM5 % 32u);
    }
}

void hal_timer_start(uint64_t at_us)
{
    uint32_t pm = stm32_irq_save();
    s_timer_at_us = at_us;
    s_timer_armed = true;
    timer_program();
    stm32_irq_restore(pm);
}

void hal_timer_cancel(void)
{
    uint32_t pm = stm32_irq_save();
    s_timer_armed = false;
    TIM_DIER(TIM5_BASE) &= ~TIM_DIER_CC1IE;
    stm32_irq_restore(pm);
}

void TIM5_IRQHandler(void)
{
    TIM_SR(TIM5_BASE) = ~TIM_SR_CC1IF;
    if (!s_timer_armed) {
        return;
    }
    if (stm32_time_us() >= s_timer_at_us) {
        timer_fire_if_due();
    } else {
        timer_program();                    /* long deadline, or compare a µs early */
    }
}

/* SysTick and TIM5 share priority 0x40, so they never preempt each other. */
void stm32_tick_hook(void)
{
    timer_fire_if_due();
}

/* ------------------------------------------------------------------- GPIO */

void hal_gpio_write(hal_line_t line, bool active)
{
    static const uint8_t pins[HAL_LINE_COUNT] = {
        [HAL_LINE_SHUTTER] = BOARD_PIN_SHUTTER,
        [HAL_LINE_FOCUS] = BOARD_PIN_FOCUS,
        [HAL_LINE_STATUS] = BOARD_PIN_STATUS,
    };
    if ((unsigned)line >= HAL_LINE_COUNT) {
        return;
    }
    /* The core refreshes the status line on every poll: write the pin only
     * when it changes (under QEMU every device access takes its global lock). */
    uint32_t mask = 1u << line;
    uint32_t pm = stm32_irq_save();
    if (((s_lines_known & mask) == 0u) || (((s_lines_level & mask) != 0u) != active)) {
        uint32_t bit = 1u << pins[line];
        GPIO_BSRR(BOARD_CTRL_PORT) = active ? bit : bit << 16;
        s_lines_known |= mask;
        s_lines_level = active ? (s_lines_level | mask) : (s_lines_level & ~mask);
    }
    stm32_irq_restore(pm);
}

void hal_led_select(int ch)
{
    /* One BSRR write: every switch off and (set wins) the chosen one on, so two
     * LEDs are never on together, not even for one bus cycle. */
    uint32_t bsrr = 0xFFFFu << 16;
    if (ch >= 0 && (unsigned)ch < BOARD_LED_CHANNELS && (unsigned)ch < FW_CFG_MAX_LEDS) {
        bsrr |= 1u << (unsigned)ch;
        s_led_channel = ch;
    } else {
        s_led_channel = -1;
    }
    GPIO_BSRR(BOARD_LED_PORT) = bsrr;
}

bool hal_button_read(void)
{
    return (GPIO_IDR(BOARD_CTRL_PORT) >> BOARD_PIN_BUTTON) & 1u;
}

void EXTI2_IRQHandler(void)
{
    uint64_t t = stm32_time_us();
    EXTI_PR = 1u << BOARD_PIN_SYNC;
    uint32_t head = s_sync_head;
    if (head - s_sync_tail < SYNC_RING) {   /* a full ring drops the newest edge */
        s_sync_t[head % SYNC_RING] = t;
        s_sync_head = head + 1u;
    }
    stm32_wake();
}

bool hal_sync_take(uint64_t *t_us)
{
    bool taken = false;
    uint32_t pm = stm32_irq_save();
    uint32_t tail = s_sync_tail;
    if (tail != s_sync_head && s_sync_t[tail % SYNC_RING] <= stm32_time_us()) {
        *t_us = s_sync_t[tail % SYNC_RING];
        s_sync_tail = tail + 1u;
        taken = true;
    }
    stm32_irq_restore(pm);
    return taken;
}

void hal_frame_annotate(const hal_frame_tag_t *tag)
{
    (void)tag;                              /* for the simulated rig only */
}

/* -------------------------------------------------------------- DAC, ADC */

void hal_dac_set(uint16_t code)
{
    if (code > FW_CFG_DAC_MAX_CODE) {
        code = FW_CFG_DAC_MAX_CODE;
    }
    s_dac_code = code;
    DAC_DHR12R1 = code;
}

/* One conversion of an ADC1 channel; -1 when it does not complete. */
static int32_t adc_convert(uint32_t channel)
{
    ADC_SQR3(ADC1_BASE) = channel;
    ADC_SR(ADC1_BASE) = 0u;
    ADC_CR2(ADC1_BASE) |= ADC_CR2_SWSTART;
    for (uint32_t i = 0; i < ADC_WAIT_LOOPS; i++) {
        if (ADC_SR(ADC1_BASE) & ADC_SR_EOC) {
            return (int32_t)(ADC_DR(ADC1_BASE) & 0xFFFu);
        }
    }
    return -1;
}

/* NTC divider reading to 0.01 degC (beta equation). An open or shorted NTC, or
 * a conversion that did not complete, reads as very hot so that the core's
 * over-temperature fault trips: no reading is never "cool". */
static int32_t ntc_centi_c(int32_t raw)
{
    if (raw <= 8 || raw >= BOARD_ADC_FULL - 8) {
        return INT16_MAX;
    }
    float r = BOARD_NTC_PULLUP_OHM * (float)raw / (float)(BOARD_ADC_FULL - raw);
    float inv_t = 1.0f / 298.15f + logf(r / BOARD_NTC_R25_OHM) / BOARD_NTC_BETA_K;
    float c = 1.0f / inv_t - 273.15f;
    return (int32_t)lrintf(c * 100.0f);
}

static int32_t adc_emulated(hal_adc_t ch)
{
    switch (ch) {
    case HAL_ADC_LED_CURRENT_MA:
        return s_led_channel >= 0
                   ? (int32_t)((uint32_t)s_dac_code * FW_CFG_DAC_FULL_SCALE_MA / FW_CFG_DAC_MAX_CODE)
                   : 0;
    case HAL_ADC_NTC_CENTI_C: return 2500;
    case HAL_ADC_SUPPLY_MV: return 12000;
    default: return 0;
    }
}

int32_t hal_adc_read(hal_adc_t ch)
{
    if (s_emulated) {
        return adc_emulated(ch);
    }
    switch (ch) {
    case HAL_ADC_LED_CURRENT_MA: {
        int32_t raw = adc_convert(BOARD_ADC_CH_CURRENT);
        /* No conversion: report 0 mA, which the core's sense check takes as an open LED. */
        return raw < 0 ? 0 : raw * BOARD_VREF_MV / BOARD_ADC_FULL / BOARD_SENSE_MV_PER_MA;
    }
    case HAL_ADC_NTC_CENTI_C:
        return ntc_centi_c(adc_convert(BOARD_ADC_CH_NTC));
    case HAL_ADC_SUPPLY_MV: {
        int32_t raw = adc_convert(BOARD_ADC_CH_SUPPLY);
        return raw < 0 ? 0 : raw * BOARD_VREF_MV * BOARD_SUPPLY_DIVIDER / BOARD_ADC_FULL;
    }
    default:
        return 0;
    }
}

/* ------------------------------------------------------------------ flash */

static uint8_t *nvm_page(unsigned page)
{
    return page == 0u ? __nvm_page0 : __nvm_page1;
}

/* Sector numbers of the two pages (stm32f405rg.ld: sectors 1 and 2). */
static uint32_t nvm_sector(unsigned page)
{
    return page == 0u ? 1u : 2u;
}

uint32_t hal_flash_page_size(void)
{
    return (uint32_t)(uintptr_t)__nvm_page_size;
}

static bool flash_wait_idle(void)
{
    for (uint32_t i = 0; i < FLASH_WAIT_LOOPS; i++) {
        if ((FLASH_SR & FLASH_SR_BSY) == 0u) {
            return (FLASH_SR & FLASH_SR_ERRORS) == 0u;
        }
    }
    return false;
}

static void flash_unlock(void)
{
    if (FLASH_CR & FLASH_CR_LOCK) {
        FLASH_KEYR = FLASH_KEY1;
        FLASH_KEYR = FLASH_KEY2;
    }
    FLASH_SR = FLASH_SR_ERRORS;             /* clear stale error flags (write 1) */
}

static void flash_lock_and_flush(void)
{
    FLASH_CR = FLASH_CR_LOCK;
    /* The ART caches may hold the old contents of the page. */
    uint32_t acr = FLASH_ACR;
    FLASH_ACR = acr & ~(FLASH_ACR_ICEN | FLASH_ACR_DCEN);
    FLASH_ACR = (acr & ~(FLASH_ACR_ICEN | FLASH_ACR_DCEN)) | FLASH_ACR_ICRST | FLASH_ACR_DCRST;
    FLASH_ACR = acr;
}

int hal_flash_erase(unsigned page)
{
    if (page > 1u) {
        return -1;
    }
    hal_watchdog_kick();                    /* the erase stalls the core for up to 0.5 s */
    flash_unlock();
    bool ok = flash_wait_idle();
    if (ok) {
        FLASH_CR = FLASH_CR_PSIZE_X32 | FLASH_CR_SER | FLASH_CR_SNB(nvm_sector(page));
        FLASH_CR |= FLASH_CR_STRT;
        ok = flash_wait_idle();
    }
    flash_lock_and_flush();
    hal_watchdog_kick();
    const uint32_t *p = (const uint32_t *)(const void *)nvm_page(page);
    for (uint32_t i = 0; ok && i < hal_flash_page_size() / 4u; i++) {
        ok = p[i] == 0xFFFFFFFFu;           /* read back: QEMU's flash is a ROM */
    }
    return ok ? 0 : -1;
}

int hal_flash_write(unsigned page, uint32_t offset, const void *data, size_t len)
{
    if (page > 1u || (offset & 3u) || (len & 3u) || offset > hal_flash_page_size() ||
        len > hal_flash_page_size() - offset) {
        return -1;
    }
    volatile uint32_t *dst = (volatile uint32_t *)(void *)(nvm_page(page) + offset);
    const uint8_t *src = data;
    size_t words = len / 4u;
    for (size_t i = 0; i < words; i++) {
        if (dst[i] != 0xFFFFFFFFu) {
            return -1;                      /* refuse to program a non-erased word */
        }
    }
    flash_unlock();
    bool ok = flash_wait_idle();
    for (size_t i = 0; ok && i < words; i++) {
        uint32_t w;
        memcpy(&w, src + 4u * i, 4u);
        FLASH_CR = FLASH_CR_PSIZE_X32 | FLASH_CR_PG;
        dst[i] = w;
        ok = flash_wait_idle();
    }
    flash_lock_and_flush();
    if (ok) {
        ok = memcmp((const void *)(nvm_page(page) + offset), data, len) == 0;
    }
    return ok ? 0 : -1;
}

int hal_flash_read(unsigned page, uint32_t offset, void *data, size_t len)
{
    if (page > 1u || offset > hal_flash_page_size() || len > hal_flash_page_size() - offset) {
        return -1;
    }
    memcpy(data, nvm_page(page) + offset, len);
    return 0;
}

/* ----------------------------------------------------------------- system */

hal_reset_cause_t hal_reset_cause(void) { return s_reset_cause; }

uint32_t hal_boot_count(void) { return s_boot_count; }

void hal_watchdog_kick(void)
{
    if (!s_wdt_started) {
        /* IWDG on the ~32 kHz LSI: /32 gives ~1 ms per count. */
        IWDG_KR = IWDG_KEY_START;
        IWDG_KR = IWDG_KEY_UNLOCK;
        IWDG_PR = 3u;
        IWDG_RLR = FW_CFG_WDT_MS > 4095u ? 4095u : FW_CFG_WDT_MS;
        for (uint32_t i = 0; i < IWDG_WAIT_LOOPS && IWDG_SR != 0u; i++) {
        }
        s_wdt_started = true;
    }
    IWDG_KR = IWDG_KEY_RELOAD;
}

void hal_critical_enter(void)
{
    uint32_t pm = stm32_irq_save();
    if (s_crit_depth++ == 0u) {
        s_crit_primask = pm;
    }
}

void hal_critical_exit(void)
{
    if (s_crit_depth > 0u && --s_crit_depth == 0u) {
        stm32_irq_restore(s_crit_primask);
    }
}

void hal_reboot(void)
{
    /* Let the last answer leave the USART before the reset cuts it. */
    uint64_t until = stm32_time_us() + 20000u;
    while (!stm32_uart_tx_idle() && stm32_time_us() < until) {
    }
    __asm volatile("dsb" ::: "memory");
    SCB_AIRCR = SCB_AIRCR_SYSRESETREQ;
    __asm volatile("dsb" ::: "memory");
    for (;;) {
    }
}

uint32_t hal_unique_id(void)
{
    if (s_emulated) {
        return EMULATED_UID;
    }
    /* Fold the 96-bit factory id (lot, wafer, X/Y) into 32 bits (FNV-1a). */
    const volatile uint8_t *uid = (const volatile uint8_t *)(uintptr_t)UID_BASE;
    uint32_t h = 2166136261u;
    for (unsigned i = 0; i < 12u; i++) {
        h = (h ^ uid[i]) * 16777619u;
    }
    return h;
}

void fw_assert_failed(const char *file, int line)
{
    (void)file;
    (void)line;
    __asm volatile("cpsid i" ::: "memory");
    for (;;) {
        /* A firmware bug: stop here; the watchdog resets the board. */
    }
}

/* ------------------------------------------------------------------- main */

int main(void)
{
    board_init();
    fw_init();
    for (;;) {
        fw_poll();
#if BOARD_IDLE_WFI
        /* Sleep until the next interrupt (byte, sync edge, timer, or the 1 ms
         * tick) unless one came while fw_poll() ran. With PRIMASK set, a
         * pending interrupt still ends WFI, so none is missed between the
         * test and the sleep; it is taken after cpsie. */
        __asm volatile("cpsid i" ::: "memory");
        if (!s_wake && !stm32_uart_rx_pending()) {
            __asm volatile("dsb\n wfi" ::: "memory");
        }
        s_wake = false;
        __asm volatile("cpsie i" ::: "memory");
#endif
    }
}
