/* seq.c - the scan sequencer: lights x exposures, three timing modes,
 * pre-focus, mirror-up, settle and gaps, flash-sync accounting with retry,
 * the frame ring.
 *
 * Every step runs from the one-shot timer at its deadline; the next deadline is
 * computed from the previous one (never from "now"), so durations are exact in
 * the timer's resolution and errors do not accumulate over a scan.
 *
 * Frame timeline per mode (t_open = shutter line active, exp = exposure_time_us[e]):
 *   all:     [focus prefocus_us][wait mirror_up_us] ...
 *   CAMERA:  LED on, settle_us, shutter 1 (t_open), shutter 0 after min(exp, release
 *            pulse), LED off at t_open + exp (the camera exposes exp from t_open)
 *   BULB:    LED on, settle_us, shutter 1 for exactly exp, shutter 0, LED off
 *   LED:     shutter 1, led_pre_us, LED on for exactly exp, LED off, led_post_us, shutter 0
 *   all:     ... sync check (wait up to t_open + sync_timeout_us), record, gap_us
 */
#include "seq.h"

#include "fw_config.h"
#include "fw_registers.h"
#include "hal.h"
#include "led.h"
#include "regs.h"
#include "safe.h"
#include "trig.h"

typedef enum {
    ST_NONE,
    ST_FOCUS,
    ST_MIRROR,
    ST_LED_ON,
    ST_OPEN,
    ST_RELEASE,
    ST_PULSE_ON,
    ST_PULSE_OFF,
    ST_CLOSE,
    ST_SYNC_WAIT,
    ST_FINISH,
} seq_step_t;

typedef struct {
    uint16_t n_lights, n_exp;
    uint8_t mode, retries;
    uint32_t prefocus, mirror, settle, gap, pre, post, sync_to;
    uint8_t order[FW_CFG_MAX_LEDS];
    uint16_t light_mA[FW_CFG_MAX_LEDS];
    uint32_t exp_us[FW_CFG_MAX_EXPOSURES];
    uint16_t exp_mA[FW_CFG_MAX_EXPOSURES];
} seq_cfg_t;

static struct {
    unsigned state;
    seq_cfg_t cfg;
    uint16_t setting; /* light * n_exp + exposure of the frame in progress / next */
    uint8_t tries;    /* retries spent on this setting */
    bool in_frame;
    seq_step_t next;
    uint64_t deadline, t_scan0, t_frame0, t_open;
    uint16_t set_mA, meas_mA;
    uint16_t done, ring, retries_used;
} s;

static void set_state(unsigned st)
{
    s.state = st;
    regs_set(FW_SLOT_STATE, st);
}

void seq_init(void)
{
    hal_timer_cancel();
    s.state = FW_STATE_IDLE;
    s.in_frame = false;
    s.next = ST_NONE;
    s.setting = s.done = s.ring = s.retries_used = 0;
    set_state(FW_STATE_IDLE);
}

bool seq_active(void)
{
    return s.state == FW_STATE_ARMED || s.state == FW_STATE_RUNNING || s.state == FW_STATE_PAUSED;
}

static void snapshot(seq_cfg_t *c)
{
    c->n_lights = (uint16_t)regs_get(FW_SLOT_N_LIGHTS);
    c->n_exp = (uint16_t)regs_get(FW_SLOT_N_EXPOSURES);
    c->mode = (uint8_t)regs_get(FW_SLOT_TIMING_MODE);
    c->retries = (uint8_t)regs_get(FW_SLOT_RETRIES);
    c->prefocus = regs_get(FW_SLOT_PREFOCUS_US);
    c->mirror = regs_get(FW_SLOT_MIRROR_UP_US);
    c->settle = regs_get(FW_SLOT_SETTLE_US);
    c->gap = regs_get(FW_SLOT_GAP_US);
    c->pre = regs_get(FW_SLOT_LED_PRE_US);
    c->post = regs_get(FW_SLOT_LED_POST_US);
    c->sync_to = regs_get(FW_SLOT_SYNC_TIMEOUT_US);
    for (unsigned i = 0; i < FW_CFG_MAX_LEDS; i++) {
        c->order[i] = (uint8_t)regs_get(FW_SLOT_LIGHT_ORDER + i);
        c->light_mA[i] = (uint16_t)regs_get(FW_SLOT_LIGHT_CURRENT_MA + i);
    }
    for (unsigned e = 0; e < FW_CFG_MAX_EXPOSURES; e++) {
        c->exp_us[e] = regs_get(FW_SLOT_EXPOSURE_TIME_US + e);
        c->exp_mA[e] = (uint16_t)regs_get(FW_SLOT_EXPOSURE_CURRENT_MA + e);
    }
}

static uint16_t frame_mA(const seq_cfg_t *c, unsigned light, unsigned e)
{
    return c->exp_mA[e] ? c->exp_mA[e] : c->light_mA[light];
}

/* LED on-time of one frame of exposure e (what max_pulse_us limits). */
static uint32_t pulse_us(const seq_cfg_t *c, unsigned e)
{
    return c->mode == FW_TIMING_MODE_LED ? c->exp_us[e] : c->settle + c->exp_us[e];
}

static uint64_t frame_us(const seq_cfg_t *c, unsigned e)
{
    uint64_t w = c->mode == FW_TIMING_MODE_LED ? (uint64_t)c->pre + c->exp_us[e] + c->post
                                               : (uint64_t)c->settle + c->exp_us[e];
    return (uint64_t)c->prefocus + c->mirror + w + c->gap;
}

fw_err_t seq_validate_config(void)
{
    seq_cfg_t c;
    snapshot(&c);
    FW_VERIFY(c.n_lights >= 1 && c.n_lights <= FW_CFG_MAX_LEDS, FW_ERR_CONFIG);
    FW_VERIFY(c.n_exp >= 1 && c.n_exp <= FW_CFG_MAX_EXPOSURES, FW_ERR_CONFIG);
    uint32_t lim = safe_max_current_mA(), max_pulse = safe_max_pulse_us();
    for (unsigned l = 0; l < c.n_lights; l++) {
        FW_VERIFY(c.order[l] < FW_CFG_MAX_LEDS, FW_ERR_CONFIG);
        for (unsigned e = 0; e < c.n_exp; e++) {
            uint32_t mA = led_gained_mA(c.order[l], frame_mA(&c, l, e));
            FW_VERIFY(mA >= 1 && mA <= lim, FW_ERR_CONFIG); /* refuse rather than clip */
        }
    }
    for (unsigned e = 0; e < c.n_exp; e++)
        FW_VERIFY(pulse_us(&c, e) <= max_pulse, FW_ERR_CONFIG);
    return FW_OK;
}

static void ring_clear(void)
{
    for (unsigned i = 0; i < FW_CFG_RING_LEN; i++)
        regs_set(FW_SLOT_RING_FLAGS + i, 0);
}

static void ring_record(bool synced, bool retry)
{
    unsigned i = s.ring % FW_CFG_RING_LEN;
    regs_set(FW_SLOT_RING_FRAME + i, s.setting);
    regs_set(FW_SLOT_RING_LIGHT + i, s.setting / s.cfg.n_exp);
    regs_set(FW_SLOT_RING_EXPOSURE + i, s.setting % s.cfg.n_exp);
    regs_set(FW_SLOT_RING_CURRENT_SET_MA + i, s.set_mA);
    regs_set(FW_SLOT_RING_CURRENT_MEAS_MA + i, s.meas_mA);
    regs_set(FW_SLOT_RING_START_US + i, (uint32_t)(s.t_open - s.t_scan0));
    regs_set(FW_SLOT_RING_FLAGS + i, (synced ? 1u : 0u) | (retry ? 2u : 0u) | 4u);
    s.ring++;
}

static void lines_off(void)
{
    led_off();
    trig_shutter(false);
    trig_focus(false);
}

/* Execute one step at time s.deadline; returns the next step and its delay. */
static seq_step_t step(seq_step_t st, uint32_t *delay)
{
    const seq_cfg_t *c = &s.cfg;
    unsigned light = s.setting / c->n_exp, e = s.setting % c->n_exp;
    int ch = c->order[light];
    uint32_t exp = c->exp_us[e];
    *delay = 0;
    switch (st) {
    case ST_FOCUS:
        s.in_frame = true;
        s.t_frame0 = s.deadline;
        s.set_mA = frame_mA(c, light, e);
        s.meas_mA = 0;
        if (c->prefocus) {
            trig_focus(true);
            *delay = c->prefocus;
        }
        return ST_MIRROR;
    case ST_MIRROR:
        *delay = c->mirror;
        return ST_LED_ON;
    case ST_LED_ON:
        if (c->mode != FW_TIMING_MODE_LED) {
            led_on(ch, s.set_mA);
            *delay = c->settle;
        }
        return ST_OPEN;
    case ST_OPEN: {
        hal_frame_tag_t tag = {s.setting, (uint16_t)light, (uint16_t)e, c->mode, exp};
        trig_sync_flush();
        hal_frame_annotate(&tag);
        trig_shutter(true);
        s.t_open = s.deadline;
        if (c->mode == FW_TIMING_MODE_CAMERA) {
            *delay = exp < FW_CFG_RELEASE_PULSE_US ? exp : FW_CFG_RELEASE_PULSE_US;
            return ST_RELEASE;
        }
        if (c->mode == FW_TIMING_MODE_BULB) {
            *delay = exp;
            return ST_CLOSE;
        }
        *delay = c->pre;
        return ST_PULSE_ON;
    }
    case ST_RELEASE:
        trig_shutter(false);
        *delay = (uint32_t)(s.t_open + exp - s.deadline);
        return ST_CLOSE;
    case ST_PULSE_ON:
        led_on(ch, s.set_mA);
        *delay = exp;
        return ST_PULSE_OFF;
    case ST_PULSE_OFF:
        if (led_check(&s.meas_mA) != FW_OK)
            return ST_NONE;
        led_off();
        *delay = c->post;
        return ST_CLOSE;
    case ST_CLOSE: {
        if (c->mode != FW_TIMING_MODE_LED) {
            if (led_check(&s.meas_mA) != FW_OK)
                return ST_NONE;
            led_off();
        }
        trig_shutter(false);
        trig_focus(false);
        uint64_t t_edge, until = s.t_open + c->sync_to;
        if (trig_sync_seen(s.t_open, &t_edge) || s.deadline >= until)
            return ST_FINISH;
        *delay = (uint32_t)(until - s.deadline);
        return ST_SYNC_WAIT;
    }
    case ST_SYNC_WAIT:
        return ST_FINISH;
    case ST_FINISH: {
        uint64_t t_edge;
        bool synced = trig_sync_seen(s.t_open, &t_edge);
        ring_record(synced, s.tries > 0);
        s.in_frame = false;
        if (synced) {
            s.done++;
            s.setting++;
            s.tries = 0;
        } else if (s.tries < c->retries) {
            s.tries++;
            s.retries_used++;
        } else {
            safe_fault(FW_FAULT_SYNC_MISSED, s.setting);
            return ST_NONE;
        }
        if (s.setting >= (unsigned)c->n_lights * c->n_exp) {
            set_state(FW_STATE_DONE);
            return ST_NONE;
        }
        if (s.state == FW_STATE_PAUSED)
            return ST_NONE;
        *delay = c->gap;
        return ST_FOCUS;
    }
    default:
        return ST_NONE;
    }
}

static void run_from(seq_step_t st)
{
    for (;;) {
        uint32_t delay;
        st = step(st, &delay);
        if (st == ST_NONE || s.state == FW_STATE_FAULT || s.state == FW_STATE_ABORTED) {
            s.next = ST_NONE;
            return;
        }
        if (delay) {
            s.next = st;
            s.deadline += delay;
            hal_timer_start(s.deadline);
            return;
        }
    }
}

void seq_on_timer(void)
{
    if (s.next == ST_NONE || (s.state != FW_STATE_RUNNING && s.state != FW_STATE_PAUSED))
        return;
    run_from(s.next);
    seq_update_status();
}

void seq_on_fault(void)
{
    hal_timer_cancel();
    s.next = ST_NONE;
    s.in_frame = false;
    set_state(FW_STATE_FAULT);
}

fw_err_t seq_command_check(unsigned cmd)
{
    switch (cmd) {
    case FW_COMMAND_ARM:
        FW_VERIFY(s.state != FW_STATE_FAULT && !safe_blocking_fault(), FW_ERR_FAULT);
        FW_VERIFY(s.state == FW_STATE_IDLE || s.state == FW_STATE_DONE ||
                      s.state == FW_STATE_ABORTED,
                  FW_ERR_STATE);
        return seq_validate_config();
    case FW_COMMAND_START:
        FW_VERIFY(s.state == FW_STATE_ARMED, FW_ERR_STATE);
        return FW_OK;
    case FW_COMMAND_ABORT:
        FW_VERIFY(seq_active(), FW_ERR_STATE);
        return FW_OK;
    case FW_COMMAND_PAUSE:
        FW_VERIFY(s.state == FW_STATE_RUNNING, FW_ERR_STATE);
        return FW_OK;
    case FW_COMMAND_RESUME:
        FW_VERIFY(s.state == FW_STATE_PAUSED, FW_ERR_STATE);
        return FW_OK;
    case FW_COMMAND_CLEAR_FAULTS:
        return FW_OK;
    default:
        return FW_ERR_VALUE;
    }
}

fw_err_t seq_command(unsigned cmd)
{
    fw_err_t e = seq_command_check(cmd);
    if (e != FW_OK)
        return e;
    hal_critical_enter();
    switch (cmd) {
    case FW_COMMAND_ARM:
        snapshot(&s.cfg);
        s.setting = s.done = s.ring = s.retries_used = 0;
        s.tries = 0;
        s.in_frame = false;
        ring_clear();
        lines_off();
        regs_set(FW_SLOT_MANUAL_CHANNEL, (uint32_t)-1);
        set_state(FW_STATE_ARMED);
        break;
    case FW_COMMAND_START:
        set_state(FW_STATE_RUNNING);
        s.deadline = s.t_scan0 = hal_time_us();
        run_from(ST_FOCUS);
        break;
    case FW_COMMAND_ABORT:
        hal_timer_cancel();
        s.next = ST_NONE;
        s.in_frame = false;
        lines_off();
        set_state(FW_STATE_ABORTED);
        break;
    case FW_COMMAND_PAUSE:
        set_state(FW_STATE_PAUSED); /* the frame in progress completes */
        break;
    case FW_COMMAND_RESUME:
        set_state(FW_STATE_RUNNING);
        if (!s.in_frame && s.next == ST_NONE) {
            s.deadline = hal_time_us();
            run_from(ST_FOCUS);
        }
        break;
    case FW_COMMAND_CLEAR_FAULTS:
        if (s.state == FW_STATE_FAULT)
            set_state(FW_STATE_IDLE);
        break;
    default:
        break;
    }
    hal_critical_exit();
    seq_update_status();
    return FW_OK;
}

void seq_update_status(void)
{
    const seq_cfg_t *c = &s.cfg;
    bool have = s.state != FW_STATE_IDLE && c->n_exp > 0;
    unsigned total = have ? (unsigned)c->n_lights * c->n_exp : 0u;
    uint64_t left = 0;
    if (have && (seq_active())) {
        for (unsigned k = s.setting; k < total; k++)
            left += frame_us(c, k % c->n_exp);
        if (left >= c->gap)
            left -= c->gap; /* no gap after the last frame */
        if (s.in_frame) {
            uint64_t el = hal_time_us() - s.t_frame0;
            left = left > el ? left - el : 0;
        }
    }
    regs_set(FW_SLOT_STATE, s.state);
    regs_set(FW_SLOT_CURRENT_LIGHT, have && s.setting < total ? s.setting / c->n_exp : 0u);
    regs_set(FW_SLOT_CURRENT_EXPOSURE, have && s.setting < total ? s.setting % c->n_exp : 0u);
    regs_set(FW_SLOT_FRAMES_DONE, s.done);
    regs_set(FW_SLOT_FRAMES_EXPECTED, total);
    regs_set(FW_SLOT_TIME_LEFT_US, left > UINT32_MAX ? UINT32_MAX : (uint32_t)left);
    regs_set(FW_SLOT_RING_COUNT, s.ring);
    regs_set(FW_SLOT_RETRIES_USED, s.retries_used);
}
