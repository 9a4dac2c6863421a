/* test_seq.c - sequencer timelines in virtual time, sync accounting, button. */
#include <string.h>

#include "fw_config.h"
#include "fw_err.h"
#include "fw_registers.h"
#include "hal.h"
#include "test.h"

static void config(unsigned mode, unsigned nl, unsigned ne, const uint32_t *exp)
{
    CHECK_EQ(th_write(FW_REG_TIMING_MODE, (uint16_t)mode), 0);
    CHECK_EQ(th_write(FW_REG_N_LIGHTS, (uint16_t)nl), 0);
    CHECK_EQ(th_write(FW_REG_N_EXPOSURES, (uint16_t)ne), 0);
    for (unsigned e = 0; e < ne; e++)
        CHECK_EQ(th_write32(FW_REG_EXPOSURE_TIME_US(e), exp[e]), 0);
    CHECK_EQ(th_write32(FW_REG_SETTLE_US, 5000), 0);
    CHECK_EQ(th_write32(FW_REG_GAP_US, 20000), 0);
    CHECK_EQ(th_write32(FW_REG_LED_PRE_US, 3000), 0);
    CHECK_EQ(th_write32(FW_REG_LED_POST_US, 2000), 0);
}

static void start(void)
{
    CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
    th.n_ev = 0;
    CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_START), 0);
}

/* k-th event of a kind with level/channel filter: a = -2 any. */
static const th_event_t *nth(th_ev_kind_t kind, int a, unsigned k)
{
    for (size_t i = 0; i < th.n_ev; i++)
        if (th.ev[i].kind == kind && (a == -2 || th.ev[i].a == a || (a == 1 && kind == TH_EV_LED && th.ev[i].a >= 0)))
            if (k-- == 0)
                return &th.ev[i];
    return NULL;
}

static unsigned count(th_ev_kind_t kind, int a)
{
    unsigned n = 0;
    while (nth(kind, a, n))
        n++;
    return n;
}

/* LED "on" events: a >= 0 (select a = 1 in nth for any channel) */
#define LED_ON(k) nth(TH_EV_LED, 1, (k))
#define LED_OFF(k) nth(TH_EV_LED, -1, (k))
#define SH_OPEN(k) nth(TH_EV_SHUTTER, 1, (k))
#define SH_CLOSE(k) nth(TH_EV_SHUTTER, 0, (k))

void test_seq(void)
{
    static const uint32_t exp2[2] = {10000, 250000};
    SHOULD("in camera mode light the LED settle_us before the release and exactly exp_us after it")
    {
        config(FW_TIMING_MODE_CAMERA, 2, 2, exp2);
        start();
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        CHECK_EQ(count(TH_EV_SHUTTER, 1), 4);
        for (unsigned k = 0; k < 4; k++) {
            const th_event_t *on = LED_ON(k), *off = LED_OFF(k), *op = SH_OPEN(k), *cl = SH_CLOSE(k);
            CHECK(on && off && op && cl);
            if (!(on && off && op && cl))
                break;
            uint32_t e = exp2[k % 2];
            CHECK_EQ(op->t - on->t, 5000);
            CHECK_EQ(off->t - op->t, e);
            CHECK_EQ(cl->t - op->t, e < 100000 ? e : 100000); /* release press */
            CHECK_EQ(op->tag.exp_us, e);
            CHECK_EQ(op->tag.mode, FW_TIMING_MODE_CAMERA);
            CHECK_EQ(on->a, k / 2); /* light_order default: channel = light */
            CHECK_EQ(on->b, 500);   /* light_current_mA default, gain 1 */
        }
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 4);
        CHECK_EQ(th_reg_in(FW_REG_RING_COUNT), 4);
    }
    SHOULD("in bulb mode hold the shutter for exactly exp_us with the LED lit across it")
    {
        config(FW_TIMING_MODE_BULB, 2, 2, exp2);
        start();
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        for (unsigned k = 0; k < 4; k++) {
            const th_event_t *on = LED_ON(k), *off = LED_OFF(k), *op = SH_OPEN(k), *cl = SH_CLOSE(k);
            CHECK(on && off && op && cl);
            if (!(on && off && op && cl))
                break;
            CHECK_EQ(cl->t - op->t, exp2[k % 2]);
            CHECK_EQ(op->t - on->t, 5000);
            CHECK(off->t >= cl->t);
            CHECK_EQ(off->t - cl->t, 0);
        }
    }
    SHOULD("in LED mode pulse the LED for exactly exp_us inside the open shutter")
    {
        static const uint32_t e3[3] = {1, 37, 123457};
        config(FW_TIMING_MODE_LED, 1, 3, e3);
        start();
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        for (unsigned k = 0; k < 3; k++) {
            const th_event_t *on = LED_ON(k), *off = LED_OFF(k), *op = SH_OPEN(k), *cl = SH_CLOSE(k);
            CHECK(on && off && op && cl);
            if (!(on && off && op && cl))
                break;
            CHECK_EQ(off->t - on->t, e3[k]);
            CHECK_EQ(on->t - op->t, 3000);
            CHECK_EQ(cl->t - off->t, 2000);
            CHECK_EQ(op->tag.mode, FW_TIMING_MODE_LED);
        }
    }
    SHOULD("hold focus for prefocus_us, wait mirror_up_us, then light; gap_us between frames")
    {
        static const uint32_t e1[1] = {40000};
        config(FW_TIMING_MODE_BULB, 2, 1, e1);
        CHECK_EQ(th_write32(FW_REG_PREFOCUS_US, 30000), 0);
        CHECK_EQ(th_write32(FW_REG_MIRROR_UP_US, 70000), 0);
        start();
        uint64_t t0 = th.now;
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        const th_event_t *f1 = nth(TH_EV_FOCUS, 1, 0), *f0 = nth(TH_EV_FOCUS, 0, 0);
        const th_event_t *on0 = LED_ON(0), *cl0 = SH_CLOSE(0), *f1b = nth(TH_EV_FOCUS, 1, 1);
        CHECK(f1 && f0 && on0 && cl0 && f1b);
        if (f1 && f0 && on0 && cl0 && f1b) {
            CHECK_EQ(f1->t, t0);
            CHECK_EQ(on0->t - f1->t, 100000);
            CHECK_EQ(f0->t, cl0->t);
            CHECK_EQ(f1b->t - cl0->t, 20000); /* gap_us */
        }
    }
    SHOULD("record light, exposure, currents, start time and sync in the frame ring")
    {
        config(FW_TIMING_MODE_LED, 2, 2, exp2);
        CHECK_EQ(th_write(FW_REG_LIGHT_ORDER(0), 7), 0);
        CHECK_EQ(th_write(FW_REG_LIGHT_CURRENT_MA(1), 800), 0);
        CHECK_EQ(th_write(FW_REG_EXPOSURE_CURRENT_MA(1), 300), 0);
        start();
        uint64_t t0 = th.now;
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        uint16_t r[32];
        CHECK_EQ(th_read(4, FW_REG_RING_FRAME(0), 32, r), 0);
        /* record 0: light 0 on channel 7, exposure 0, 500 mA */
        CHECK_EQ(r[0], 0);
        CHECK_EQ(r[1], 0);
        CHECK_EQ(r[2], 0);
        CHECK_EQ(r[3], 500);
        CHECK_EQ(r[4], 500);
        CHECK_EQ(((uint32_t)r[5] << 16 | r[6]), SH_OPEN(0)->t - t0);
        CHECK_EQ(r[7], 5); /* valid + sync */
        CHECK_EQ(r[8 + 3], 300);  /* exposure 1 uses its own current */
        CHECK_EQ(r[16 + 1], 1);   /* record 2: light 1 */
        CHECK_EQ(r[16 + 3], 800);
        CHECK_EQ(LED_ON(0)->a, 7);
    }
    SHOULD("repeat a setting once when its flash-sync is missing and still finish the scan")
    {
        config(FW_TIMING_MODE_BULB, 2, 2, exp2);
        start();
        th.miss_sync = 1;
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 4);
        CHECK_EQ(th_reg_in(FW_REG_RING_COUNT), 5);
        CHECK_EQ(th_reg_in(FW_REG_RETRIES_USED), 1);
        CHECK_EQ(th_reg_in(FW_REG_RING_FLAGS(0)), 4); /* valid, no sync */
        CHECK_EQ(th_reg_in(FW_REG_RING_FLAGS(1)), 7); /* valid, sync, retry */
        CHECK_EQ(th_reg_in(FW_REG_RING_FRAME(1)), 0); /* the same setting again */
        CHECK_EQ(count(TH_EV_SHUTTER, 1), 5);
    }
    SHOULD("fault with SYNC_MISSED and lights off when the retry misses its sync too")
    {
        config(FW_TIMING_MODE_BULB, 2, 2, exp2);
        start();
        th.miss_sync = 2;
        CHECK(th_run_until_state(FW_STATE_FAULT, 5000000));
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_SYNC_MISSED));
        CHECK_EQ(th.led_ch, -1);
        CHECK(!th.shutter);
        CHECK_EQ(th_reg_in(FW_REG_FAULT_LOG_COUNT), 2); /* CAL_INVALID at boot, then this */
        CHECK_EQ(th_reg_in(FW_REG_FAULT_LOG_CODE(1)), FW_FAULT_SYNC_MISSED);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 4); /* latched */
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_CLEAR_FAULTS), 0);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_IDLE);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
    }
    SHOULD("count a sync that arrives after the window but within sync_timeout_us")
    {
        config(FW_TIMING_MODE_BULB, 1, 1, exp2);
        th.sync_delay_us = 300000; /* window is 10 ms, timeout 500 ms */
        start();
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 1);
        CHECK_EQ(th_reg_in(FW_REG_RETRIES_USED), 0);
    }
    SHOULD("finish the frame in progress on PAUSE, take no frame while paused, go on at RESUME")
    {
        config(FW_TIMING_MODE_BULB, 2, 2, exp2);
        start();
        th_advance(6000); /* inside frame 0's exposure */
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_PAUSE), 0);
        th_advance(2000000);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_PAUSED);
        CHECK_EQ(count(TH_EV_SHUTTER, 0), 1);
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 1);
        CHECK_EQ(th.led_ch, -1);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_RESUME), 0);
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 4);
    }
    SHOULD("switch everything off at once on ABORT")
    {
        config(FW_TIMING_MODE_BULB, 2, 2, exp2);
        start();
        th_advance(8000);
        CHECK(th.shutter && th.led_ch == 0);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ABORT), 0);
        CHECK(!th.shutter && th.led_ch == -1 && !th.focus);
        th_advance(1000000);
        CHECK_EQ(count(TH_EV_SHUTTER, 1), 1);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_ABORTED);
    }
    SHOULD("start the configured scan on a button press, ignore bounces, abort on a second press")
    {
        config(FW_TIMING_MODE_BULB, 2, 2, exp2);
        th.button = true;
        th_advance(5000); /* 5 ms bounce */
        th.button = false;
        th_advance(50000);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_IDLE);
        th.button = true;
        th_advance(30000);
        th.button = false;
        th_advance(30000);
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_RUNNING);
        th.button = true;
        th_advance(30000);
        th.button = false;
        CHECK_EQ(th_reg_in(FW_REG_STATE), FW_STATE_ABORTED);
        CHECK_EQ(th.led_ch, -1);
    }
    SHOULD("refuse ARM when a pulse would exceed max_pulse_us or a current max_current_mA")
    {
        static const uint32_t longexp[1] = {20000000};
        config(FW_TIMING_MODE_BULB, 1, 1, longexp); /* settle 5 ms + 20 s > 20 s */
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 4);
        CHECK_EQ((int16_t)th_reg_in(FW_REG_LAST_ERROR), FW_ERR_CONFIG);
        CHECK_EQ(th_write(FW_REG_TIMING_MODE, FW_TIMING_MODE_LED), 0); /* pulse = 20 s: fine */
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ABORT), 0);
        CHECK_EQ(th_write(FW_REG_LIGHT_CURRENT_MA(0), 1200), 0); /* > max_current 1000 */
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 4);
    }
    SHOULD("estimate the time left exactly and count it down")
    {
        config(FW_TIMING_MODE_LED, 2, 2, exp2);
        start();
        /* per frame: pre 3000 + exp + post 2000 + gap 20000; no gap after the last */
        uint32_t total = 2 * (25000 + 10000) + 2 * (25000 + 250000) - 20000;
        CHECK_EQ(th_reg_in32(FW_REG_TIME_LEFT_US), total);
        th_advance(100000);
        CHECK_EQ(th_reg_in32(FW_REG_TIME_LEFT_US), total - 100000);
        CHECK(th_run_until_state(FW_STATE_DONE, 5000000));
        CHECK_EQ(th_reg_in32(FW_REG_TIME_LEFT_US), 0);
    }
    SHOULD("run the largest scan (16 lights x 16 exposures) and wrap the frame ring")
    {
        static uint32_t e16[16];
        for (unsigned e = 0; e < 16; e++)
            e16[e] = 100u + 7u * e;
        config(FW_TIMING_MODE_LED, 16, 16, e16);
        start();
        CHECK(th_run_until_state(FW_STATE_DONE, 60000000));
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_DONE), 256);
        CHECK_EQ(th_reg_in(FW_REG_FRAMES_EXPECTED), 256);
        CHECK_EQ(th_reg_in(FW_REG_RING_COUNT), 256);
        CHECK_EQ(th_reg_in(FW_REG_RING_FRAME(15)), 255); /* record 255 -> entry 255 % 16 */
        CHECK_EQ(th_reg_in(FW_REG_RING_LIGHT(15)), 15);
        CHECK_EQ(th_reg_in(FW_REG_RING_EXPOSURE(15)), 15);
        CHECK_EQ(th_reg_in(FW_REG_RING_FRAME(0)), 240);
        const th_event_t *on = LED_ON(255), *off = LED_OFF(255);
        CHECK(on && off && off->t - on->t == e16[15] && on->a == 15);
    }
    SHOULD("record the derated measured current next to the set one when the LEDs run hot")
    {
        static const uint32_t e1[1] = {30000};
        config(FW_TIMING_MODE_BULB, 1, 1, e1);
        th.ntc_cC = 7000;
        th_advance(20000);
        start();
        CHECK(th_run_until_state(FW_STATE_DONE, 3000000));
        CHECK_EQ(th_reg_in(FW_REG_RING_CURRENT_SET_MA(0)), 500);
        CHECK_EQ(th_reg_in(FW_REG_RING_CURRENT_MEAS_MA(0)), 250);
        CHECK_EQ(LED_ON(0)->b, 250);
    }
}
