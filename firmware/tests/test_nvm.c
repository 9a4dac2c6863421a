/* test_nvm.c - the calibration store: unlock, save, two pages, power loss. */
#include <string.h>

#include "fw_registers.h"
#include "nvm.h"
#include "test.h"

static void unlock(void) { CHECK_EQ(th_write(FW_REG_CAL_UNLOCK, FW_UNLOCK_KEY), 0); }

static void save_gains(uint16_t first, uint32_t serial)
{
    unlock();
    for (unsigned i = 0; i < 16; i++)
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(i), (uint16_t)(first + i)), 0);
    CHECK_EQ(th_write32(FW_REG_CAL_SERIAL, serial), 0);
    CHECK_EQ(th_write(FW_REG_COMMAND, FW_COMMAND_SAVE), 0);
}

void test_nvm(void)
{
    SHOULD("keep saved gains and serial number across a power cycle")
    {
        save_gains(9000, 4242);
        th_boot(HAL_RESET_POWER_ON);
        CHECK_EQ(th_reg_hold(FW_REG_CAL_GAIN(0)), 9000);
        CHECK_EQ(th_reg_hold(FW_REG_CAL_GAIN(15)), 9015);
        CHECK_EQ(th_reg_in32(FW_REG_SERIAL_NUMBER), 4242);
        CHECK_EQ(th_reg_in32(FW_REG_CAL_SEQUENCE), 1);
        CHECK_EQ(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_CAL_INVALID), 0);
    }
    SHOULD("use defaults and latch CAL_INVALID when no page holds a valid record")
    {
        CHECK(th_reg_in(FW_REG_FAULT_BITS) & (1u << FW_FAULT_CAL_INVALID));
        CHECK_EQ(th_reg_hold(FW_REG_CAL_GAIN(7)), 10000);
        CHECK_EQ(th_reg_in32(FW_REG_CAL_SEQUENCE), 0);
    }
    SHOULD("alternate pages and load the newest record")
    {
        save_gains(6000, 1);
        save_gains(7000, 2);
        save_gains(8000, 3);
        th_boot(HAL_RESET_POWER_ON);
        CHECK_EQ(th_reg_hold(FW_REG_CAL_GAIN(0)), 8000);
        CHECK_EQ(th_reg_in32(FW_REG_CAL_SEQUENCE), 3);
        /* records 2 and 3 sit in different pages */
        uint32_t s0, s1;
        memcpy(&s0, &th.flash[0][4], 4);
        memcpy(&s1, &th.flash[1][4], 4);
        CHECK((s0 == 3 && s1 == 2) || (s0 == 2 && s1 == 3));
    }
    SHOULD("fall back to the older record when the newest page is corrupted")
    {
        save_gains(6000, 1);
        save_gains(7000, 2);
        unsigned newest = th.flash[0][4] == 2 ? 0u : 1u;
        th.flash[newest][20] ^= 0x01;
        th_boot(HAL_RESET_POWER_ON);
        CHECK_EQ(th_reg_hold(FW_REG_CAL_GAIN(0)), 6000);
        CHECK_EQ(th_reg_in32(FW_REG_CAL_SEQUENCE), 1);
    }
    SHOULD("survive a power loss at every byte of a save: old or new record, never a mix")
    {
        /* cost of one save: erase 1024 bytes + program 48 */
        int bad = 0, olds = 0, news = 0;
        for (long cut = 0; cut <= 1024 + 48 + 1; cut++) {
            th_fresh();
            save_gains(6000, 1);
            save_gains(6500, 2); /* the next save targets the page of record 1 */
            unlock();
            for (unsigned i = 0; i < 16; i++)
                th_write(FW_REG_CAL_GAIN(i), (uint16_t)(7000 + i));
            th.flash_budget = cut;
            th_write(FW_REG_COMMAND, FW_COMMAND_SAVE); /* the power dies inside */
            th_boot(HAL_RESET_POWER_ON);
            uint16_t g0 = th_reg_hold(FW_REG_CAL_GAIN(0)), g15 = th_reg_hold(FW_REG_CAL_GAIN(15));
            uint32_t seq = th_reg_in32(FW_REG_CAL_SEQUENCE);
            if (g0 == 6500 && g15 == 6515 && seq == 2)
                olds++;
            else if (g0 == 7000 && g15 == 7015 && seq == 3)
                news++;
            else
                bad++;
        }
        CHECK_EQ(bad, 0);
        CHECK(olds > 1000);
        CHECK(news >= 1); /* with the whole budget the new record is there */
    }
    SHOULD("refuse calibration writes after the unlock expires or a wrong key")
    {
        unlock();
        CHECK_EQ(th_reg_hold(FW_REG_CAL_UNLOCK), 1);
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(0), 12000), 0);
        th_advance(FW_CFG_UNLOCK_TIMEOUT_US + 1000);
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(0), 12000), 4);
        CHECK_EQ(th_reg_in(FW_REG_CAL_UNLOCKED), 0);
        unlock();
        CHECK_EQ(th_write(FW_REG_CAL_UNLOCK, 1234), 0);
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(0), 12000), 4);
    }
    SHOULD("relock after SAVE")
    {
        save_gains(9000, 1);
        CHECK_EQ(th_reg_in(FW_REG_CAL_UNLOCKED), 0);
        CHECK_EQ(th_write(FW_REG_CAL_GAIN(0), 9500), 4);
    }
    SHOULD("compute the CRC-32 of the check string (0xCBF43926)")
    {
        CHECK_EQ(nvm_crc32("123456789", 9), 0xCBF43926u);
    }
}
