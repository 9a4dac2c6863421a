/* nvm.c - calibration store in two flash pages.
 *
 * Each save goes to the page that does not hold the current record: erase,
 * program the body, program the CRC word last. A power loss at any point leaves
 * either the old record (the other page is untouched) or the new one complete;
 * a torn page fails its CRC and is ignored. The newest valid record wins
 * (sequence numbers compared modulo 2^32). */
#include "nvm.h"

#include <string.h>

#include "hal.h"

#define NVM_MAGIC 0x43414C31u /* "CAL1" */

typedef struct {
    uint32_t magic;
    uint32_t seq;
    uint32_t serial;
    uint16_t gain[FW_CFG_MAX_LEDS];
    uint32_t crc; /* CRC-32 of everything before it; programmed last */
} nvm_record_t;

_Static_assert(sizeof(nvm_record_t) % 4u == 0, "record must be whole flash words");

static int s_page = -1; /* page holding the record in use */

uint32_t nvm_crc32(const void *data, size_t len)
{
    const uint8_t *p = data;
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < len; i++) {
        crc ^= p[i];
        for (int b = 0; b < 8; b++)
            crc = (crc & 1u) ? (crc >> 1) ^ 0xEDB88320u : crc >> 1;
    }
    return ~crc;
}

static bool read_valid(unsigned page, nvm_record_t *r)
{
    if (hal_flash_read(page, 0, r, sizeof *r) != 0)
        return false;
    return r->magic == NVM_MAGIC && r->crc == nvm_crc32(r, offsetof(nvm_record_t, crc));
}

static void defaults(nvm_cal_t *cal)
{
    cal->seq = 0;
    cal->serial = 0;
    for (unsigned i = 0; i < FW_CFG_MAX_LEDS; i++)
        cal->gain[i] = 10000u;
}

fw_err_t nvm_load(nvm_cal_t *cal)
{
    nvm_record_t r[2];
    bool ok[2] = {read_valid(0, &r[0]), read_valid(1, &r[1])};
    int best = -1;
    if (ok[0] && ok[1])
        best = (int32_t)(r[1].seq - r[0].seq) > 0 ? 1 : 0;
    else if (ok[0] || ok[1])
        best = ok[0] ? 0 : 1;
    s_page = best;
    if (best < 0) {
        defaults(cal);
        return FW_ERR_FLASH;
    }
    cal->seq = r[best].seq;
    cal->serial = r[best].serial;
    for (unsigned i = 0; i < FW_CFG_MAX_LEDS; i++) {
        uint16_t g = r[best].gain[i];
        cal->gain[i] = (g >= 5000u && g <= 20000u) ? g : 10000u;
    }
    return FW_OK;
}

fw_err_t nvm_save(nvm_cal_t *cal)
{
    nvm_record_t r;
    memset(&r, 0xFF, sizeof r);
    r.magic = NVM_MAGIC;
    r.seq = cal->seq + 1u;
    if (r.seq == 0)
        r.seq = 1; /* 0 means "nothing stored" */
    r.serial = cal->serial;
    memcpy(r.gain, cal->gain, sizeof r.gain);
    r.crc = nvm_crc32(&r, offsetof(nvm_record_t, crc));
    unsigned page = s_page == 0 ? 1u : 0u;
    FW_VERIFY(hal_flash_page_size() >= sizeof r, FW_ERR_FLASH);
    FW_VERIFY(hal_flash_erase(page) == 0, FW_ERR_FLASH);
    FW_VERIFY(hal_flash_write(page, 0, &r, offsetof(nvm_record_t, crc)) == 0, FW_ERR_FLASH);
    FW_VERIFY(hal_flash_write(page, offsetof(nvm_record_t, crc), &r.crc, sizeof r.crc) == 0,
              FW_ERR_FLASH);
    nvm_record_t check;
    FW_VERIFY(read_valid(page, &check) && check.seq == r.seq, FW_ERR_FLASH);
    s_page = (int)page;
    cal->seq = r.seq;
    return FW_OK;
}
