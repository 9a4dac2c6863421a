/* test_mb.c - CRC, framing, function codes, range checks of every register. */
#define FW_REGISTERS_IMPL
#include <string.h>

#include "fw_config.h"
#include "fw_registers.h"
#include "mb.h"
#include "regs.h"
#include "test.h"

static void send_bytes(const uint8_t *b, const uint32_t *gaps, size_t n, uint32_t idle)
{
    memcpy(th.rx, b, n);
    memcpy(th.rx_gap, gaps, n * sizeof *gaps);
    th.rx_len = n;
    th.rx_pos = 0;
    th.tx_len = 0;
    th.idle_us = idle;
    fw_poll();
}

static void check_range_of(const fw_reg_desc_t *d)
{
    /* min-1 and max+1 answer 03 and change nothing; min and max are accepted */
    uint16_t addr = d->addr;
    int is32 = d->type == FW_REG_U32;
    long long lo = d->min, hi = d->max == -1 ? 0xFFFFFFFFll : d->max;
    long long tmin = d->type == FW_REG_I16 ? -32768 : 0;
    long long tmax = d->type == FW_REG_I16 ? 32767 : is32 ? 0xFFFFFFFFll : 0xFFFF;
    uint32_t before = regs_get(d->slot);
    if (lo > tmin) {
        int r = is32 ? th_write32(addr, (uint32_t)(lo - 1)) : th_write(addr, (uint16_t)(lo - 1));
        CHECK_EQ(r, 3);
        CHECK_EQ(regs_get(d->slot), before);
    }
    if (hi < tmax) {
        int r = is32 ? th_write32(addr, (uint32_t)(hi + 1)) : th_write(addr, (uint16_t)(hi + 1));
        CHECK_EQ(r, 3);
        CHECK_EQ(regs_get(d->slot), before);
    }
}

void test_mb(void)
{
    SHOULD("compute the Modbus CRC of the specification's example (01 03 00 00 00 0A -> C5 CD)")
    {
        const uint8_t f[] = {0x01, 0x03, 0x00, 0x00, 0x00, 0x0A};
        CHECK_EQ(mb_crc16(f, sizeof f), 0xCDC5);
        CHECK_EQ(mb_crc16(f, 0), 0xFFFF);
    }
    SHOULD("end a frame only after 3.5 characters (1750 us) of silence")
    {
        uint8_t req[8] = {1, 3, 0x11, 0x00, 0, 1};
        uint16_t c = mb_crc16(req, 6);
        req[6] = (uint8_t)c;
        req[7] = (uint8_t)(c >> 8);
        uint32_t gaps[8] = {100000, 0, 0, 0, 0, 0, 0, 0};
        send_bytes(req, gaps, 8, 1700);
        CHECK_EQ(th.tx_len, 0); /* 1700 us: not yet */
        th.idle_us = 1750;
        fw_poll();
        CHECK_EQ(th.tx_len, 7);
    }
    SHOULD("split two frames separated by a 3.5-character gap and answer both")
    {
        uint8_t two[16] = {1, 3, 0x11, 0x00, 0, 1, 0, 0, 1, 3, 0x11, 0x01, 0, 1, 0, 0};
        uint16_t c = mb_crc16(two, 6);
        two[6] = (uint8_t)c;
        two[7] = (uint8_t)(c >> 8);
        c = mb_crc16(two + 8, 6);
        two[14] = (uint8_t)c;
        two[15] = (uint8_t)(c >> 8);
        uint32_t gaps[16] = {100000};
        gaps[8] = 2000;
        send_bytes(two, gaps, 16, 5000);
        CHECK_EQ(th.tx_len, 14);
        CHECK_EQ(th.tx[4], 12); /* n_lights */
        CHECK_EQ(th.tx[7 + 4], 7); /* n_exposures */
    }
    SHOULD("drop a frame with an inner gap longer than 1.5 characters (750 us)")
    {
        uint8_t req[8] = {1, 3, 0x11, 0x00, 0, 1};
        uint16_t c = mb_crc16(req, 6);
        req[6] = (uint8_t)c;
        req[7] = (uint8_t)(c >> 8);
        uint32_t gaps[8] = {100000, 0, 0, 800, 0, 0, 0, 0};
        send_bytes(req, gaps, 8, 5000);
        CHECK_EQ(th.tx_len, 0);
        uint32_t ok[8] = {100000, 0, 0, 700, 0, 0, 0, 0}; /* 700 us is allowed */
        send_bytes(req, ok, 8, 5000);
        CHECK_EQ(th.tx_len, 7);
    }
    SHOULD("drop a frame longer than 256 bytes and answer the next one")
    {
        static uint8_t big[300];
        static uint32_t gaps[300];
        memset(big, 1, sizeof big);
        gaps[0] = 100000;
        send_bytes(big, gaps, sizeof big, 5000);
        CHECK_EQ(th.tx_len, 0);
        CHECK_EQ(th_reg_hold(FW_REG_N_LIGHTS), 12);
    }
    SHOULD("refuse out-of-range values with exception 03 for every holding register")
    {
        for (unsigned i = 0; i < FW_REG_HOLDING_COUNT; i++)
            check_range_of(&fw_reg_holding_table[i]);
    }
    SHOULD("read every input and holding register alone and all of each space in blocks")
    {
        uint16_t v[125];
        for (unsigned i = 0; i < FW_REG_INPUT_COUNT; i++) {
            const fw_reg_desc_t *d = &fw_reg_input_table[i];
            CHECK_EQ(th_read(4, d->addr, d->type == FW_REG_U32 ? 2 : 1, v), 0);
        }
        for (unsigned i = 0; i < FW_REG_HOLDING_COUNT; i++) {
            const fw_reg_desc_t *d = &fw_reg_holding_table[i];
            CHECK_EQ(th_read(3, d->addr, d->type == FW_REG_U32 ? 2 : 1, v), 0);
        }
        CHECK_EQ(th_read(4, FW_REG_RING_FRAME(0), 125, v), 0); /* ring: 16 x 8 contiguous */
        CHECK_EQ(th_read(3, FW_REG_LIGHT_ORDER(0), 16 * 3 + 32, v), 0);
    }
    SHOULD("write a mix of u16 and u32 registers with one function 16 request")
    {
        uint8_t req[64] = {1, 16, 0x11, 0x00, 0, 6, 12, 0, 3, 0, 2, 0, 1, 0, 1, 0, 0, 0, 0x20};
        /* n_lights 3, n_exposures 2, timing_mode 1 (bulb), retries 1, prefocus_us 32 */
        uint8_t resp[64];
        CHECK_EQ(th_transact_crc(req, 19, resp), 8);
        CHECK_EQ(th_reg_hold(FW_REG_N_LIGHTS), 3);
        CHECK_EQ(th_reg_hold(FW_REG_TIMING_MODE), 1);
        CHECK_EQ(regs_get(FW_SLOT_PREFOCUS_US), 32);
    }
    SHOULD("report the definition hash, firmware version and the device identity")
    {
        CHECK_EQ(th_reg_in32(FW_REG_DEFINITION_HASH), FW_DEFINITION_HASH);
        CHECK_EQ(th_reg_in(FW_REG_FW_VERSION), FW_CFG_FW_VERSION);
        CHECK_EQ(th_reg_in(FW_REG_BOOT_COUNT), 1);
        CHECK_EQ(th_reg_in(FW_REG_RESET_CAUSE), FW_RESET_CAUSE_POWER_ON);
        CHECK_EQ(th_reg_in32(FW_REG_SERIAL_NUMBER), 0xC0FFEE01u); /* unique id: nothing stored */
    }
    SHOULD("answer REBOOT first, then restart with reset cause SOFTWARE and boot count 2")
    {
        uint8_t req[8] = {1, 6, 0x10, 0x00, 0, FW_COMMAND_REBOOT};
        uint8_t resp[16];
        CHECK_EQ(th_transact_crc(req, 6, resp), 8);
        CHECK_EQ(th_reg_in(FW_REG_RESET_CAUSE), FW_RESET_CAUSE_SOFTWARE);
        CHECK_EQ(th_reg_in(FW_REG_BOOT_COUNT), 2);
    }
    SHOULD("refuse configuration writes with exception 04 while a scan is armed")
    {
        CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_ARM), 0);
        CHECK_EQ(th_write(FW_REG_N_LIGHTS, 3), 4);
        CHECK_EQ(th_write32(FW_REG_EXPOSURE_TIME_US(0), 1000), 4);
        CHECK_EQ(th_write(FW_REG_MANUAL_CHANNEL, 2), 4);
        CHECK_EQ((int16_t)th_reg_in(FW_REG_LAST_ERROR), FW_ERR_STATE);
        CHECK_EQ(th_write(FW_REG_HOST_WATCHDOG_MS, 100), 0); /* not scan configuration */
    }
    SHOULD("accept the largest write (123 registers) and the full u32 range where allowed")
    {
        static uint8_t req[300] = {1, 16, 0x11, 0x20, 0, 80, 160};
        /* light_order[16], light_current_mA[16], exposure_time_us[16] (u32), exposure_current_mA[16] */
        for (unsigned i = 0; i < 16; i++) {
            req[7 + 2 * i + 1] = (uint8_t)(15 - i);
            req[7 + 32 + 2 * i + 1] = 100;
            req[7 + 64 + 4 * i + 3] = 50;
            req[7 + 128 + 2 * i + 1] = 0;
        }
        uint8_t resp[300];
        CHECK_EQ(th_transact_crc(req, 7 + 160, resp), 8);
        CHECK_EQ(th_reg_hold(FW_REG_LIGHT_ORDER(0)), 15);
        CHECK_EQ(regs_get(FW_SLOT_EXPOSURE_TIME_US + 15), 50);
        uint8_t big[16] = {1, 16, 0x11, 0x00, 0, 124, 248, 0, 1};
        CHECK_EQ(th_transact_crc(big, 9, resp), 5); /* quantity 124 > 123: exception 03 */
        CHECK_EQ(resp[2], 3);
        CHECK_EQ(th_write(FW_REG_CAL_UNLOCK, FW_UNLOCK_KEY), 0);
        CHECK_EQ(th_write32(FW_REG_CAL_SERIAL, 0xFFFFFFFFu), 0);
        CHECK_EQ(regs_get(FW_SLOT_CAL_SERIAL), 0xFFFFFFFFu);
    }
}
