/*
 * hal_posix.c - the simulated device: the HAL on a POSIX host.
 *
 * UART: a pseudo-terminal (the master side here; the host opens the slave).
 *
 * Clock: virtual microseconds, running `speed` times real time. The one-shot
 * timer never lets the clock pass its deadline: when virtual time would cross
 * it, the clock is set exactly to the deadline and fw_on_timer() runs, so the
 * sequencer's pulses and windows are exact in virtual time whatever the speed.
 *
 * Modbus framing decision: the 3.5-character silence is measured in REAL time
 * here (bytes are timestamped with CLOCK_MONOTONIC when read from the pty, and
 * hal_uart_idle_us() is real time since the last byte). The peer on the pty is
 * a real-time process (pymodbus, pyserial) whose inter-frame pauses are real; at
 * --speed 1000 a 1750 us virtual silence would be 1.75 ns real and every pause
 * inside the host's write would split frames. Bytes read in one chunk are
 * back to back on the "line" (gap 0).
 *
 * Side channel (--side SOCKET, one client at a time), ASCII lines:
 *   out: "<t_us> led <ch> <mA>", "<t_us> shutter <0|1> frame=.. light=.. exp=..
 *        exp_us=.. mode=camera|bulb|led", "<t_us> focus <0|1>", "<t_us> boot <n>"
 *   in:  ack, sync <t_us>, button <0|1>, ntc <centi_degC>, led_fault <ch>
 *        <open|short|ok>, supply <mV>, biterr <p>, reset, miss_sync <n>
 * Lockstep: while a client is connected, each led/shutter event freezes the
 * virtual clock until the client's "ack" for it has been read. Without a client,
 * events are dropped, and an ideal camera answers each shutter opening with a
 * flash-sync edge at the same instant (unless miss_sync is pending).
 * A client that hung up is read to the end before it is let go: `echo
 * "miss_sync 2" | nc -U SOCKET` works even if it is gone before we accept it. Once
 * an event cannot be written to it, it counts as no client (no lockstep, the
 * ideal camera answers) while its last lines are read.
 * Event times are virtual us since the process started (monotonic across
 * resets); hal_time_us() counts from the last reset.
 *
 * Not simulated: the hardware watchdog (a hung core stops this loop too).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "fw_config.h"
#include "posix_port.h"

volatile int posix_stop;

#define RX_CAP 4096u
#define SYNC_CAP 32u

static struct {
    /* configuration */
    double speed;
    char link_path[512], side_path[512], state_dir[512];
    /* pty */
    int master, slave;
    char pty_name[128];
    /* side channel */
    int listen_fd, client;
    bool client_deaf; /* writing to the client failed: read its last lines, send nothing */
    char line[512];
    size_t line_len;
    unsigned pending_acks;
    /* clocks */
    uint64_t v_now, v_anchor, v_boot; /* virtual us since process start */
    uint64_t r_anchor;                /* real us (CLOCK_MONOTONIC) at v_anchor */
    bool timer_armed;
    uint64_t timer_at; /* absolute virtual us */
    /* uart */
    uint8_t rx[RX_CAP];
    uint32_t rx_gap[RX_CAP];
    size_t rx_head, rx_tail;
    uint64_t r_last_rx;
    bool rx_ever;
    double biterr;
    /* lines */
    bool shutter, focus;
    int led_ch;
    uint16_t dac;
    bool led_on_reported;
    int reported_ch;
    unsigned reported_mA;
    hal_frame_tag_t tag;
    /* inputs */
    bool button;
    int32_t ntc_cC, supply_mV;
    uint8_t led_fault[FW_CFG_MAX_LEDS]; /* 0 ok, 1 open, 2 short */
    unsigned miss_sync;
    bool drop_sync; /* the current shutter opening gets no sync */
    uint64_t sync_q[SYNC_CAP];        /* absolute virtual us */
    unsigned sync_n;
    /* system */
    uint8_t flash[2][POSIX_FLASH_PAGE];
    uint32_t boot_count;
    hal_reset_cause_t cause;
    bool reboot;
} P;

static const char *const k_mode[] = {"camera", "bulb", "led"};

/* ---- helpers ------------------------------------------------------------ */
static uint64_t real_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

static void reanchor(void)
{
    P.v_anchor = P.v_now;
    P.r_anchor = real_us();
}

static void side_close(void)
{
    if (P.client >= 0)
        close(P.client);
    P.client = -1;
    P.client_deaf = false;
    P.pending_acks = 0;
    P.line_len = 0;
    reanchor();
}

/* A client that hears the events (and acks them). */
static bool side_listening(void) { return P.client >= 0 && !P.client_deaf; }

static void side_send(bool needs_ack, const char *fmt, ...)
{
    if (!side_listening())
        return;
    char buf[256];
    int n = snprintf(buf, sizeof buf, "%llu ", (unsigned long long)P.v_now);
    va_list ap;
    va_start(ap, fmt);
    n += vsnprintf(buf + n, sizeof buf - (size_t)n, fmt, ap);
    va_end(ap);
    if (n >= (int)sizeof buf - 1)
        n = (int)sizeof buf - 2;
    buf[n++] = '\n';
    size_t off = 0;
    while (off < (size_t)n) {
        ssize_t w = write(P.client, buf + off, (size_t)n - off);
        if (w < 0 && errno == EINTR)
            continue;
        if (w < 0 && errno == EAGAIN) {
            struct pollfd pf = {P.client, POLLOUT, 0};
            poll(&pf, 1, 100);
            continue;
        }
        if (w <= 0) {
            /* it hung up (EPIPE), maybe with lines not read yet: side_pump reads
             * them and closes at end of file */
            P.client_deaf = true;
            P.pending_acks = 0;
            reanchor();
            return;
        }
        off += (size_t)w;
    }
    if (needs_ack) {
        P.pending_acks++;
    }
}

static bool frozen(void) { return side_listening() && P.pending_acks > 0; }

static uint8_t maybe_corrupt(uint8_t b)
{
    if (P.biterr > 0 && (double)random() / ((double)RAND_MAX + 1.0) < P.biterr)
        b ^= (uint8_t)(1u << (random() % 8));
    return b;
}

static void flash_persist(void)
{
    if (!P.state_dir[0])
        return;
    char path[600];
    snprintf(path, sizeof path, "%s/flash.bin", P.state_dir);
    FILE *f = fopen(path, "wb");
    if (!f) {
        fprintf(stderr, "facette-device: cannot write %s: %s\n", path, strerror(errno));
        return;
    }
    fwrite(P.flash, 1, sizeof P.flash, f);
    fclose(f);
}

/* ---- UART --------------------------------------------------------------- */
uint32_t hal_uart_baud(void) { return 115200u; }

int hal_uart_getc(uint32_t *gap_us)
{
    if (P.rx_head == P.rx_tail)
        return -1;
    uint8_t b = P.rx[P.rx_tail];
    *gap_us = P.rx_gap[P.rx_tail];
    P.rx_tail = (P.rx_tail + 1u) % RX_CAP;
    return b;
}

uint32_t hal_uart_idle_us(void)
{
    if (!P.rx_ever)
        return UINT32_MAX;
    uint64_t d = real_us() - P.r_last_rx;
    return d > UINT32_MAX ? UINT32_MAX : (uint32_t)d;
}

void hal_uart_write(const uint8_t *data, size_t len)
{
    uint8_t buf[512];
    if (len > sizeof buf)
        len = sizeof buf;
    for (size_t i = 0; i < len; i++)
        buf[i] = maybe_corrupt(data[i]);
    size_t off = 0;
    int tries = 0;
    while (off < len) {
        ssize_t w = write(P.master, buf + off, len - off);
        if (w < 0 && (errno == EINTR || errno == EAGAIN) && ++tries < 100) {
            struct pollfd pf = {P.master, POLLOUT, 0};
            poll(&pf, 1, 10); /* nobody reading the pty: give up after ~1 s */
            continue;
        }
        if (w <= 0)
            return;
        off += (size_t)w;
    }
}

static void uart_pump(void)
{
    uint8_t buf[512];
    for (;;) {
        ssize_t n = read(P.master, buf, sizeof buf);
        if (n <= 0)
            return;
        uint64_t now = real_us();
        uint64_t gap = P.rx_ever ? now - P.r_last_rx : UINT32_MAX;
        for (ssize_t i = 0; i < n; i++) {
            size_t next = (P.rx_head + 1u) % RX_CAP;
            if (next == P.rx_tail)
                break; /* overrun: drop */
            P.rx[P.rx_head] = maybe_corrupt(buf[i]);
            P.rx_gap[P.rx_head] = i == 0 ? (gap > UINT32_MAX ? UINT32_MAX : (uint32_t)gap) : 0u;
            P.rx_head = next;
        }
        P.r_last_rx = now;
        P.rx_ever = true;
    }
}

/* ---- clock and timer --------------------------------------------------- */
uint64_t hal_time_us(void) { return P.v_now - P.v_boot; }

void hal_timer_start(uint64_t at_us)
{
    P.timer_armed = true;
    P.timer_at = at_us + P.v_boot;
}

void hal_timer_cancel(void) { P.timer_armed = false; }

/* ---- GPIO, LED sink ----------------------------------------------------- */
static unsigned dac_mA(uint16_t code)
{
    return (unsigned)(((uint32_t)code * FW_CFG_DAC_FULL_SCALE_MA + FW_CFG_DAC_MAX_CODE / 2u) /
                      FW_CFG_DAC_MAX_CODE);
}

static void led_report(void)
{
    bool on = P.led_ch >= 0 && P.dac > 0;
    unsigned mA = on ? dac_mA(P.dac) : 0u;
    if (on && (!P.led_on_reported || P.reported_ch != P.led_ch || P.reported_mA != mA)) {
        side_send(true, "led %d %u", P.led_ch, mA);
    } else if (!on && P.led_on_reported) {
        side_send(true, "led -1 0");
    } else {
        return;
    }
    P.led_on_reported = on;
    P.reported_ch = on ? P.led_ch : -1;
    P.reported_mA = mA;
}

void hal_gpio_write(hal_line_t line, bool active)
{
    if (line == HAL_LINE_SHUTTER && active != P.shutter) {
        P.shutter = active;
        if (active) {
            P.drop_sync = P.miss_sync > 0;
            if (P.drop_sync)
                P.miss_sync--;
            side_send(true, "shutter 1 frame=%u light=%u exp=%u exp_us=%lu mode=%s", P.tag.frame,
                      P.tag.light, P.tag.exposure, (unsigned long)P.tag.exp_us,
                      k_mode[P.tag.mode < 3 ? P.tag.mode : 0]);
            if (!side_listening() && !P.drop_sync && P.sync_n < SYNC_CAP)
                P.sync_q[P.sync_n++] = P.v_now; /* the built-in ideal camera */
        } else {
            side_send(true, "shutter 0 frame=%u light=%u exp=%u exp_us=%lu mode=%s", P.tag.frame,
                      P.tag.light, P.tag.exposure, (unsigned long)P.tag.exp_us,
                      k_mode[P.tag.mode < 3 ? P.tag.mode : 0]);
        }
    } else if (line == HAL_LINE_FOCUS && active != P.focus) {
        P.focus = active;
        side_send(false, "focus %d", active ? 1 : 0);
    }
}

void hal_led_select(int ch)
{
    P.led_ch = ch < (int)FW_CFG_MAX_LEDS ? ch : -1;
    led_report();
}

void hal_dac_set(uint16_t code)
{
    P.dac = code > FW_CFG_DAC_MAX_CODE ? (uint16_t)FW_CFG_DAC_MAX_CODE : code;
    led_report();
}

bool hal_button_read(void) { return P.button; }

bool hal_sync_take(uint64_t *t_us)
{
    if (P.sync_n == 0)
        return false;
    unsigned best = 0;
    for (unsigned i = 1; i < P.sync_n; i++)
        if (P.sync_q[i] < P.sync_q[best])
            best = i;
    if (P.sync_q[best] > P.v_now)
        return false;
    *t_us = P.sync_q[best] - P.v_boot;
    P.sync_q[best] = P.sync_q[--P.sync_n];
    return true;
}

void hal_frame_annotate(const hal_frame_tag_t *tag) { P.tag = *tag; }

int32_t hal_adc_read(hal_adc_t ch)
{
    switch (ch) {
    case HAL_ADC_LED_CURRENT_MA: {
        if (P.led_ch < 0)
            return 0;
        int32_t mA = (int32_t)dac_mA(P.dac);
        uint8_t f = P.led_fault[P.led_ch];
        return f == 1 ? 0 : f == 2 ? mA * 16 / 10 : mA;
    }
    case HAL_ADC_NTC_CENTI_C: return P.ntc_cC;
    case HAL_ADC_SUPPLY_MV: return P.supply_mV;
    default: return 0;
    }
}

/* ---- flash ---------------------------------------------------------------- */
uint32_t hal_flash_page_size(void) { return POSIX_FLASH_PAGE; }

int hal_flash_erase(unsigned page)
{
    if (page > 1)
        return -1;
    memset(P.flash[page], 0xFF, POSIX_FLASH_PAGE);
    flash_persist();
    return 0;
}

int hal_flash_write(unsigned page, uint32_t offset, const void *data, size_t len)
{
    if (page > 1 || offset % 4u || len % 4u || offset + len > POSIX_FLASH_PAGE)
        return -1;
    const uint8_t *d = data;
    for (size_t i = 0; i < len; i++)
        P.flash[page][offset + i] &= d[i]; /* NOR flash: programming only clears bits */
    flash_persist();
    return memcmp(&P.flash[page][offset], data, len) == 0 ? 0 : -1;
}

int hal_flash_read(unsigned page, uint32_t offset, void *data, size_t len)
{
    if (page > 1 || offset + len > POSIX_FLASH_PAGE)
        return -1;
    memcpy(data, &P.flash[page][offset], len);
    return 0;
}

/* ---- system ----------------------------------------------------------------- */
hal_reset_cause_t hal_reset_cause(void) { return P.cause; }
uint32_t hal_boot_count(void) { return P.boot_count; }
void hal_watchdog_kick(void) {}
void hal_critical_enter(void) {}
void hal_critical_exit(void) {}
void hal_reboot(void) { P.reboot = true; }
uint32_t hal_unique_id(void) { return 0x5A000001u; }

void fw_assert_failed(const char *file, int line)
{
    fprintf(stderr, "facette-device: firmware assertion failed at %s:%d\n", file, line);
    abort();
}

/* ---- side channel input --------------------------------------------------- */
static void side_command(char *line)
{
    char *arg = strchr(line, ' ');
    if (arg)
        *arg++ = '\0';
    const char *a = arg ? arg : "";
    if (!strcmp(line, "ack")) {
        if (P.pending_acks > 0 && --P.pending_acks == 0)
            reanchor();
    } else if (!strcmp(line, "sync")) {
        uint64_t t = *a ? strtoull(a, NULL, 10) : P.v_now;
        if (t < P.v_now)
            t = P.v_now;
        if (!P.drop_sync && P.sync_n < SYNC_CAP)
            P.sync_q[P.sync_n++] = t;
    } else if (!strcmp(line, "button")) {
        P.button = atoi(a) != 0;
    } else if (!strcmp(line, "ntc")) {
        P.ntc_cC = (int32_t)strtol(a, NULL, 10);
    } else if (!strcmp(line, "supply")) {
        P.supply_mV = (int32_t)strtol(a, NULL, 10);
    } else if (!strcmp(line, "biterr")) {
        P.biterr = strtod(a, NULL);
    } else if (!strcmp(line, "miss_sync")) {
        P.miss_sync = (unsigned)strtoul(a, NULL, 10);
    } else if (!strcmp(line, "reset")) {
        posix_boot(HAL_RESET_PIN);
    } else if (!strcmp(line, "led_fault")) {
        char kind[16] = "";
        int ch = -1;
        if (sscanf(a, "%d %15s", &ch, kind) == 2 && ch >= 0 && ch < (int)FW_CFG_MAX_LEDS &&
            (!strcmp(kind, "ok") || !strcmp(kind, "open") || !strcmp(kind, "short")))
            P.led_fault[ch] = !strcmp(kind, "open") ? 1 : !strcmp(kind, "short") ? 2 : 0;
        else
            fprintf(stderr, "facette-device: side: led_fault wants '<ch> open|short|ok', got '%s'\n", a);
    } else if (line[0]) {
        fprintf(stderr, "facette-device: side: unknown command '%s'\n", line);
    }
}

static void side_pump(void)
{
    if (P.listen_fd >= 0 && P.client < 0) {
        int c = accept(P.listen_fd, NULL, NULL);
        if (c >= 0) {
            fcntl(c, F_SETFL, O_NONBLOCK);
            P.client = c;
            P.pending_acks = 0;
            P.line_len = 0;
            side_send(false, "boot %u", P.boot_count);
        }
    }
    if (P.client < 0)
        return;
    char buf[512];
    for (;;) {
        ssize_t n = read(P.client, buf, sizeof buf);
        if (n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR)) {
            side_close();
            return;
        }
        if (n < 0)
            return;
        for (ssize_t i = 0; i < n; i++) {
            char ch = buf[i];
            if (ch == '\n') {
                P.line[P.line_len] = '\0';
                if (P.line_len && P.line[P.line_len - 1] == '\r')
                    P.line[P.line_len - 1] = '\0';
                P.line_len = 0;
                side_command(P.line);
                if (P.client < 0)
                    return;
            } else if (P.line_len + 1 < sizeof P.line) {
                P.line[P.line_len++] = ch;
            }
        }
    }
}

/* ---- main loop ---------------------------------------------------------------- */
static void load_state(void)
{
    memset(P.flash, 0xFF, sizeof P.flash);
    P.boot_count = 0;
    if (!P.state_dir[0])
        return;
    char path[600];
    snprintf(path, sizeof path, "%s/flash.bin", P.state_dir);
    FILE *f = fopen(path, "rb");
    if (f) {
        if (fread(P.flash, 1, sizeof P.flash, f) != sizeof P.flash)
            memset(P.flash, 0xFF, sizeof P.flash);
        fclose(f);
    }
    snprintf(path, sizeof path, "%s/boot_count", P.state_dir);
    f = fopen(path, "r");
    if (f) {
        unsigned long v = 0;
        if (fscanf(f, "%lu", &v) == 1)
            P.boot_count = (uint32_t)v;
        fclose(f);
    }
}

static void save_boot_count(void)
{
    if (!P.state_dir[0])
        return;
    char path[600];
    snprintf(path, sizeof path, "%s/boot_count", P.state_dir);
    FILE *f = fopen(path, "w");
    if (f) {
        fprintf(f, "%lu\n", (unsigned long)P.boot_count);
        fclose(f);
    }
}

int posix_open(const char *link_path, const char *side_path, const char *state_dir, double speed)
{
    memset(&P, 0, sizeof P);
    P.client = P.listen_fd = P.master = P.slave = -1;
    P.speed = speed;
    P.led_ch = P.reported_ch = -1;
    P.ntc_cC = 2500;
    P.supply_mV = 12000;
    srandom(12345u);
    if (state_dir) {
        snprintf(P.state_dir, sizeof P.state_dir, "%s", state_dir);
        if (mkdir(state_dir, 0755) != 0 && errno != EEXIST) {
            fprintf(stderr, "facette-device: --state %s: %s\n", state_dir, strerror(errno));
            return -1;
        }
    }
    load_state();
    P.master = posix_openpt(O_RDWR | O_NOCTTY);
    if (P.master < 0 || grantpt(P.master) || unlockpt(P.master) ||
        ptsname_r(P.master, P.pty_name, sizeof P.pty_name)) {
        fprintf(stderr, "facette-device: cannot create a pseudo-terminal: %s\n", strerror(errno));
        return -1;
    }
    /* Keep the slave open ourselves: the pty then survives the host closing it. */
    P.slave = open(P.pty_name, O_RDWR | O_NOCTTY);
    struct termios tio;
    if (P.slave >= 0 && tcgetattr(P.slave, &tio) == 0) {
        cfmakeraw(&tio);
        cfsetspeed(&tio, B115200);
        tcsetattr(P.slave, TCSANOW, &tio);
    }
    if (tcgetattr(P.master, &tio) == 0) {
        cfmakeraw(&tio);
        tcsetattr(P.master, TCSANOW, &tio);
    }
    fcntl(P.master, F_SETFL, O_NONBLOCK);
    if (link_path) {
        snprintf(P.link_path, sizeof P.link_path, "%s", link_path);
        unlink(link_path);
        if (symlink(P.pty_name, link_path) != 0) {
            fprintf(stderr, "facette-device: --link %s: %s\n", link_path, strerror(errno));
            return -1;
        }
    }
    if (side_path) {
        struct sockaddr_un sa;
        memset(&sa, 0, sizeof sa);
        sa.sun_family = AF_UNIX;
        if (strlen(side_path) >= sizeof sa.sun_path) {
            fprintf(stderr, "facette-device: --side %s: path longer than %zu bytes\n", side_path,
                    sizeof sa.sun_path - 1);
            return -1;
        }
        snprintf(P.side_path, sizeof P.side_path, "%s", side_path);
        strcpy(sa.sun_path, side_path);
        unlink(side_path);
        P.listen_fd = socket(AF_UNIX, SOCK_STREAM, 0);
        if (P.listen_fd < 0 || bind(P.listen_fd, (struct sockaddr *)&sa, sizeof sa) ||
            listen(P.listen_fd, 1)) {
            fprintf(stderr, "facette-device: --side %s: %s\n", side_path, strerror(errno));
            return -1;
        }
        fcntl(P.listen_fd, F_SETFL, O_NONBLOCK);
    }
    printf("port: %s\n", P.pty_name);
    fflush(stdout);
    reanchor();
    return 0;
}

void posix_boot(hal_reset_cause_t cause)
{
    /* hard reset: every output low, inputs from the outside world kept */
    P.cause = cause;
    P.reboot = false;
    P.timer_armed = false;
    P.sync_n = 0;
    P.miss_sync = 0;
    P.drop_sync = false;
    P.shutter = P.focus = false;
    P.led_ch = -1;
    P.dac = 0;
    led_report();
    P.rx_head = P.rx_tail = 0;
    P.v_boot = P.v_now;
    P.boot_count++;
    save_boot_count();
    side_send(false, "boot %u", P.boot_count);
    fw_init();
}

bool posix_reboot_requested(void) { return P.reboot; }

void posix_step(void)
{
    side_pump();
    uart_pump();
    if (!frozen()) {
        uint64_t r = real_us();
        uint64_t target = P.v_anchor + (uint64_t)((double)(r - P.r_anchor) * P.speed);
        while (P.timer_armed && P.timer_at <= target && !frozen() && !P.reboot) {
            if (P.timer_at > P.v_now)
                P.v_now = P.timer_at;
            P.timer_armed = false;
            fw_on_timer();
        }
        if (frozen() || P.reboot)
            reanchor(); /* time stands still until the acks arrive */
        else if (target > P.v_now)
            P.v_now = target;
    }
    fw_poll();
    if (P.reboot)
        return;
    /* sleep until input, the next timer deadline (in real time) or 1 ms */
    struct pollfd pf[3];
    nfds_t n = 0;
    pf[n++] = (struct pollfd){P.master, POLLIN, 0};
    if (P.client >= 0)
        pf[n++] = (struct pollfd){P.client, POLLIN, 0};
    else if (P.listen_fd >= 0)
        pf[n++] = (struct pollfd){P.listen_fd, POLLIN, 0};
    int64_t wait_us = 1000;
    if (!frozen() && P.timer_armed) {
        double d = (double)(P.timer_at > P.v_now ? P.timer_at - P.v_now : 0) / P.speed;
        if (d < (double)wait_us)
            wait_us = (int64_t)d;
    }
    if (P.rx_head != P.rx_tail)
        wait_us = 0;
    struct timespec ts = {0, (long)wait_us * 1000L};
    ppoll(pf, n, &ts, NULL);
}

void posix_close(void)
{
    if (P.link_path[0])
        unlink(P.link_path);
    if (P.side_path[0])
        unlink(P.side_path);
    side_close();
    if (P.slave >= 0)
        close(P.slave);
    if (P.master >= 0)
        close(P.master);
}
