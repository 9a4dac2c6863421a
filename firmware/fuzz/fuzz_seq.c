/* fuzz_seq.c - libFuzzer target: the sequencer and the safety paths in virtual
 * time.
 *
 * The input is a list of operations on a freshly booted core (test HAL, virtual
 * clock, one-shot timer fired exactly at its deadline):
 *   op % 8 == 0  write one holding register     [index][4 value bytes]
 *          1     command                        [command]
 *          2     let virtual time pass          [mantissa][exponent]
 *          3     change an input of the rig     [which][2 value bytes]
 *          4     a small scan configuration     [lights][exposures][mode][exposure]
 *          5     read registers (status)        [index][count]
 *          6     reset the MCU                  [cause]
 *          7     write a block of registers     [index][count][2 bytes per register]
 * The bits above op % 8 refine it (value in the register's range or raw, main
 * loop period). Register writes and commands go through the Modbus server, as
 * a host's would. Each input may spend at most FZ_POLL_BUDGET main-loop passes.
 *
 * Checked at every LED select / DAC change and after every main-loop pass,
 * timer expiry and request (abort() on a violation, so libFuzzer keeps it):
 *   - the sink current asked of the HAL never exceeds safe_max_current_mA() nor
 *     FW_CFG_HARD_MAX_MA (compared as DAC codes, exactly);
 *   - a pulse lit by the sequencer lasts at most safe_max_pulse_us() (exactly:
 *     the pulses are timer-driven and checked at ARM); a manual light at most
 *     that plus one main-loop period (the pulse watchdog runs in the loop); never
 *     more than FW_CFG_HARD_MAX_PULSE_US plus that period;
 *   - one LED at a time: the sink never switches from one lit channel to
 *     another without going dark in between;
 *   - a lit LED has an owner: the sequencer while RUNNING or PAUSED, or the
 *     manual channel register naming that channel;
 *   - a blocking fault means light off, camera lines released, no scan active;
 *     a fault that asks for the light off (blocking or host silent) has it off
 *     at the end of the step that latched it. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fw_config.h"
#include "fw_registers.h"
#include "hal_test.h"
#include "mb.h"
#include "regmap.h"
#include "regs.h"
#include "safe.h"
#include "seq.h"

#define FZ_POLL_BUDGET 8000u
#define FZ_COARSE_POLL_US FW_CFG_SAFE_SAMPLE_US

static const uint32_t k_poll_us[4] = {500u, 2000u, 10000u, 50000u};

static struct {
    unsigned polls_left;
    bool lit_by_seq; /* the pulse now lit was switched on by the sequencer */
    uint16_t log_count;
    uint32_t boots;
    bool button_seen; /* button level at the last advance (a change is debounced) */
} F;

static void violated(const char *what)
{
    fprintf(stderr, "fuzz_seq: invariant violated: %s (t=%llu us, ch=%d, dac=%u, state=%u)\n",
            what, (unsigned long long)th.now, th.led_ch, th.dac, regs_get(FW_SLOT_STATE));
    abort();
}

/* DAC code the sink would be set to for mA (as led.c rounds it). */
static uint32_t code_for_mA(uint32_t mA)
{
    return (mA * FW_CFG_DAC_MAX_CODE + FW_CFG_DAC_FULL_SCALE_MA / 2u) / FW_CFG_DAC_FULL_SCALE_MA;
}

static bool lit(void) { return th.led_ch >= 0 && th.dac > 0; }

static void check_current(void)
{
    if (!lit())
        return;
    if (th.dac > code_for_mA(FW_CFG_HARD_MAX_MA))
        violated("sink current above FW_CFG_HARD_MAX_MA");
    if (th.dac > code_for_mA(safe_max_current_mA()))
        violated("sink current above safe_max_current_mA()");
}

static void on_led(int prev_ch, uint16_t prev_dac)
{
    bool was_lit = prev_ch >= 0 && prev_dac > 0;
    if (was_lit && th.led_ch >= 0 && th.led_ch != prev_ch)
        violated("switched from one lit LED to another without going dark");
    if (!was_lit && lit())
        F.lit_by_seq = seq_active();
    check_current();
}

static bool light_off_code(unsigned code)
{
    return code == FW_FAULT_OVERTEMP || code == FW_FAULT_LED_OPEN || code == FW_FAULT_LED_SHORT ||
           code == FW_FAULT_SYNC_MISSED || code == FW_FAULT_MAX_PULSE ||
           code == FW_FAULT_SUPPLY_LOW || code == FW_FAULT_HOST_SILENT;
}

static void on_step(void)
{
    if (th.boots != F.boots) { /* a reset cleared the fault log */
        F.boots = th.boots;
        F.log_count = 0;
    }
    check_current();
    if (lit()) {
        uint64_t on = th.now - th.led_lit_at;
        uint64_t slack = F.lit_by_seq ? 0u : th.poll_us;
        if (on > (uint64_t)FW_CFG_HARD_MAX_PULSE_US + slack)
            violated("pulse longer than FW_CFG_HARD_MAX_PULSE_US");
        if (on > (uint64_t)safe_max_pulse_us() + slack)
            violated("pulse longer than safe_max_pulse_us()");
        if (F.lit_by_seq) {
            unsigned st = regs_get(FW_SLOT_STATE);
            if (st != FW_STATE_RUNNING && st != FW_STATE_PAUSED)
                violated("sequencer's LED lit outside RUNNING/PAUSED");
        } else if (regs_get_i(FW_SLOT_MANUAL_CHANNEL) != th.led_ch) {
            violated("LED lit that manual_channel does not name");
        }
    }
    if (safe_blocking_fault()) {
        if (lit())
            violated("LED lit under a blocking fault");
        if (th.shutter || th.focus)
            violated("camera line held under a blocking fault");
        if (seq_active())
            violated("scan active under a blocking fault");
    }
    uint16_t n = (uint16_t)regs_get(FW_SLOT_FAULT_LOG_COUNT);
    for (uint16_t k = F.log_count; k != n; k++) {
        unsigned code = regs_get(FW_SLOT_FAULT_LOG_CODE + k % FW_CFG_FAULT_LOG_LEN);
        if (light_off_code(code) && lit())
            violated("LED still lit after a fault that turns it off");
    }
    F.log_count = n;
    if (F.polls_left)
        F.polls_left--;
}

/* ---- operations --------------------------------------------------------- */
/* The holding registers that are not array elements: 80 of the 101 holding
 * registers are, and picking from the table alone would rarely touch these. */
static const uint16_t k_scalars[] = {
    FW_REG_COMMAND,       FW_REG_HOST_WATCHDOG_MS, FW_REG_MANUAL_CHANNEL, FW_REG_MANUAL_CURRENT_MA,
    FW_REG_N_LIGHTS,      FW_REG_N_EXPOSURES,      FW_REG_TIMING_MODE,    FW_REG_RETRIES,
    FW_REG_PREFOCUS_US,   FW_REG_MIRROR_UP_US,     FW_REG_SETTLE_US,      FW_REG_GAP_US,
    FW_REG_LED_PRE_US,    FW_REG_LED_POST_US,      FW_REG_SYNC_TIMEOUT_US, FW_REG_CAL_UNLOCK,
    FW_REG_CAL_SERIAL,    FW_REG_MAX_CURRENT_MA,   FW_REG_TEMP_DERATE_CC, FW_REG_TEMP_FAULT_CC,
    FW_REG_MAX_PULSE_US,
};

/* index < 128: one of k_scalars; else any holding register, arrays included. */
static const fw_reg_desc_t *holding(uint8_t index)
{
    unsigned n, word;
    if (index < 128u) {
        uint16_t addr = k_scalars[index % (sizeof k_scalars / sizeof k_scalars[0])];
        return regmap_find(FW_SPACE_HOLDING, addr, &word);
    }
    const fw_reg_desc_t *t = regmap_table(FW_SPACE_HOLDING, &n);
    return &t[index % n];
}

static uint32_t pick_value(const fw_reg_desc_t *d, uint32_t raw, bool in_range)
{
    if (in_range) {
        int64_t lo = d->min, hi = d->type == FW_REG_U32 && d->max == -1 ? 0xFFFFFFFFll : d->max;
        return (uint32_t)(lo + (int64_t)(raw % (uint64_t)(hi - lo + 1)));
    }
    return d->type == FW_REG_U32 ? raw : raw & 0xFFFFu;
}

/* Modbus write of one register (06, or 16 for a u32) at its address. */
static void write_reg(uint16_t addr, uint8_t type, uint32_t v)
{
    uint8_t req[16], resp[300];
    req[0] = FW_CFG_MB_UNIT_ID;
    req[2] = (uint8_t)(addr >> 8);
    req[3] = (uint8_t)addr;
    if (type == FW_REG_U32) {
        req[1] = 0x10;
        req[4] = 0;
        req[5] = 2;
        req[6] = 4;
        req[7] = (uint8_t)(v >> 24);
        req[8] = (uint8_t)(v >> 16);
        req[9] = (uint8_t)(v >> 8);
        req[10] = (uint8_t)v;
        th_transact_crc(req, 11, resp);
    } else {
        req[1] = 0x06;
        req[4] = (uint8_t)(v >> 8);
        req[5] = (uint8_t)v;
        th_transact_crc(req, 6, resp);
    }
}

static void write_slot_reg(uint16_t addr, uint32_t v) { write_reg(addr, FW_REG_U16, v); }

/* Let us of virtual time pass, the main loop running every poll_us. Unless a
 * manual light is on (whose pulse watchdog runs in the loop) or the button just
 * changed, the loop only samples temperature and supply, every
 * FW_CFG_SAFE_SAMPLE_US: the scan's steps run from the timer, at their exact
 * deadlines. Then it runs every FZ_COARSE_POLL_US: the same faults, fewer passes. */
static void advance(uint32_t us, uint32_t poll_us)
{
    uint64_t end = th.now + us;
    while (th.now < end && F.polls_left) {
        bool fine = (lit() && !F.lit_by_seq) || th.button != F.button_seen;
        F.button_seen = th.button;
        th.poll_us = !fine && poll_us < FZ_COARSE_POLL_US ? FZ_COARSE_POLL_US : poll_us;
        uint64_t chunk = (uint64_t)th.poll_us * 16u;
        th_advance(end - th.now < chunk ? end - th.now : chunk);
    }
    th.poll_us = 500;
}

static void set_input(uint8_t which, uint8_t a, uint8_t b)
{
    uint16_t v = (uint16_t)(a << 8 | b);
    switch (which % 8u) {
    case 0: th.ntc_cC = (int16_t)v; break;          /* any temperature, 0.01 degC */
    case 1: th.ntc_cC = 2500 + b * 30; break;        /* 25 .. 101.5 degC: derate, fault */
    case 2: th.supply_mV = (int32_t)v; break;
    case 3: th.led_fault[a % 16u] = (uint8_t)(b % 3u); break;
    case 4: th.button = a & 1u; break;
    case 5: th.miss_sync = a % 5u; break;
    case 6: th.auto_sync = a & 1u; th.sync_delay_us = (uint32_t)b * 1000u; break;
    default: th.cause = HAL_RESET_POWER_ON; break;
    }
}

/* A scan the sequencer will accept more often than random writes would give. */
static void small_scan(uint8_t lights, uint8_t exps, uint8_t mode, uint8_t e)
{
    write_slot_reg(FW_REG_N_LIGHTS, 1u + lights % 4u);
    write_slot_reg(FW_REG_N_EXPOSURES, 1u + exps % 3u);
    write_slot_reg(FW_REG_TIMING_MODE, mode % 3u);
    for (unsigned k = 0; k < 3; k++)
        write_reg(FW_REG_EXPOSURE_TIME_US(k), FW_REG_U32, 1000u + (uint32_t)e * 997u * (k + 1u));
    write_reg(FW_REG_SETTLE_US, FW_REG_U32, (uint32_t)(mode >> 2) * 1000u);
    write_reg(FW_REG_GAP_US, FW_REG_U32, (uint32_t)(e & 7u) * 1000u);
}

static void read_regs(uint8_t index, uint8_t count)
{
    uint8_t req[8], resp[300];
    unsigned n;
    const fw_reg_desc_t *t = regmap_table((index & 0x80u) ? FW_SPACE_HOLDING : FW_SPACE_INPUT, &n);
    uint16_t addr = t[index % n].addr;
    uint16_t qty = (uint16_t)(1u + count % 32u);
    req[0] = FW_CFG_MB_UNIT_ID;
    req[1] = (index & 0x80u) ? 0x03 : 0x04;
    req[2] = (uint8_t)(addr >> 8);
    req[3] = (uint8_t)addr;
    req[4] = 0;
    req[5] = (uint8_t)qty;
    th_transact_crc(req, 6, resp);
}

static void write_block(const uint8_t *p, size_t avail, size_t *used)
{
    uint8_t req[FW_CFG_MB_MAX_FRAME], resp[300];
    if (avail < 2) {
        *used = avail;
        return;
    }
    uint16_t addr = holding(p[0])->addr;
    size_t qty = 1u + p[1] % 16u;
    if (qty * 2u > avail - 2u)
        qty = (avail - 2u) / 2u;
    *used = 2u + qty * 2u;
    if (qty == 0)
        return;
    req[0] = FW_CFG_MB_UNIT_ID;
    req[1] = 0x10;
    req[2] = (uint8_t)(addr >> 8);
    req[3] = (uint8_t)addr;
    req[4] = 0;
    req[5] = (uint8_t)qty;
    req[6] = (uint8_t)(2u * qty);
    memcpy(&req[7], &p[2], 2u * qty);
    th_transact_crc(req, 7u + 2u * qty, resp);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    th_fresh();
    F.polls_left = FZ_POLL_BUDGET;
    F.lit_by_seq = false;
    F.boots = th.boots;
    F.button_seen = false;
    F.log_count = (uint16_t)regs_get(FW_SLOT_FAULT_LOG_COUNT);
    th.step_hook = on_step;
    th.led_hook = on_led;
    static const uint8_t k_args[8] = {5, 1, 2, 3, 4, 2, 1, 0};
    size_t i = 0;
    while (i < size && F.polls_left) {
        uint8_t op = data[i++];
        size_t need = k_args[op % 8u];
        uint8_t a[5] = {0};
        if (op % 8u != 7u) {
            if (need > size - i)
                break;
            memcpy(a, &data[i], need);
            i += need;
        }
        switch (op % 8u) {
        case 0: {
            const fw_reg_desc_t *d = holding(a[0]);
            uint32_t raw = (uint32_t)a[1] << 24 | (uint32_t)a[2] << 16 | (uint32_t)a[3] << 8 | a[4];
            write_reg(d->addr, d->type, pick_value(d, raw, (op & 0x08u) == 0));
            break;
        }
        case 1: write_slot_reg(FW_REG_COMMAND, (op & 0x08u) ? a[0] : a[0] % 9u); break;
        case 2: {
            uint32_t us = (uint32_t)(a[0] + 1u) << (a[1] % 22u); /* 1 us .. 9 min */
            advance(us, k_poll_us[(op >> 3) & 3u]);
            break;
        }
        case 3: set_input(a[0], a[1], a[2]); break;
        case 4: small_scan(a[0], a[1], a[2], a[3]); break;
        case 5: read_regs(a[0], a[1]); break;
        case 6:
            th_boot((hal_reset_cause_t)(a[0] % 6u));
            F.lit_by_seq = false;
            on_step();
            break;
        default: {
            size_t used;
            write_block(&data[i], size - i, &used);
            i += used;
            break;
        }
        }
    }
    /* the end of every input: let a scan or a light in progress run out */
    if (seq_active() || lit())
        advance(60000000u, 10000u);
    return 0;
}
