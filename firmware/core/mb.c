/* mb.c - Modbus RTU server: CRC, 3.5-character framing, PDU dispatch,
 * register reads and writes through the application's callbacks.
 * Exceptions are produced in one place: mb_exception_for(). */
#include "mb.h"

#include <string.h>

#include "fw_config.h"
#include "hal.h"
#include "regmap.h"

enum {
    MB_EX_ILLEGAL_FUNCTION = 0x01,
    MB_EX_ILLEGAL_DATA_ADDRESS = 0x02,
    MB_EX_ILLEGAL_DATA_VALUE = 0x03,
    MB_EX_SERVER_DEVICE_FAILURE = 0x04,
};

uint16_t mb_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < len; i++) {
        crc ^= data[i];
        for (int b = 0; b < 8; b++)
            crc = (crc & 1u) ? (uint16_t)((crc >> 1) ^ 0xA001u) : (uint16_t)(crc >> 1);
    }
    return crc;
}

uint8_t mb_exception_for(fw_err_t err)
{
    switch (err) {
    case FW_ERR_FUNCTION: return MB_EX_ILLEGAL_FUNCTION;
    case FW_ERR_ADDRESS: return MB_EX_ILLEGAL_DATA_ADDRESS;
    case FW_ERR_VALUE: return MB_EX_ILLEGAL_DATA_VALUE;
    default: return MB_EX_SERVER_DEVICE_FAILURE;
    }
}

static const mb_callbacks_t *s_cb;

static uint16_t be16(const uint8_t *p)
{
    return (uint16_t)((uint16_t)p[0] << 8 | p[1]);
}

/* Every address of a read must exist in that space (else FW_ERR_ADDRESS);
 * out receives the big-endian register bytes. */
static fw_err_t read_registers(fw_reg_space_t space, uint16_t addr, uint16_t qty, uint8_t *out)
{
    FW_VERIFY((uint32_t)addr + qty <= 0x10000u, FW_ERR_ADDRESS);
    for (unsigned i = 0; i < qty; i++) {
        unsigned word;
        if (!regmap_find(space, (uint16_t)(addr + i), &word))
            return FW_ERR_ADDRESS;
    }
    for (unsigned i = 0; i < qty; i++) {
        unsigned word;
        const fw_reg_desc_t *d = regmap_find(space, (uint16_t)(addr + i), &word);
        uint32_t v = s_cb->read(d->slot);
        uint16_t w = d->type == FW_REG_U32 ? (uint16_t)(word == 0 ? v >> 16 : v) : (uint16_t)v;
        out[2 * i] = (uint8_t)(w >> 8);
        out[2 * i + 1] = (uint8_t)w;
    }
    return FW_OK;
}

/* Holding-register write in the passes described at mb_callbacks_t. */
static fw_err_t write_registers(uint16_t addr, uint16_t qty, const uint8_t *in)
{
    FW_VERIFY((uint32_t)addr + qty <= 0x10000u, FW_ERR_ADDRESS);
    /* pass 1: addresses exist and every u32 is written whole */
    for (unsigned i = 0; i < qty;) {
        unsigned word;
        const fw_reg_desc_t *d = regmap_find(FW_SPACE_HOLDING, (uint16_t)(addr + i), &word);
        FW_VERIFY(d != NULL, FW_ERR_ADDRESS);
        if (d->type == FW_REG_U32) {
            FW_VERIFY(word == 0 && i + 1u < qty, FW_ERR_ADDRESS);
            i += 2;
        } else {
            i += 1;
        }
    }
    /* pass 2: ranges, then the application's own checks (state, lock), then store */
    for (int pass = 0; pass < 3; pass++) {
        for (unsigned i = 0; i < qty;) {
            unsigned word;
            const fw_reg_desc_t *d = regmap_find(FW_SPACE_HOLDING, (uint16_t)(addr + i), &word);
            uint32_t v = (uint32_t)in[2 * i] << 8 | in[2 * i + 1];
            if (d->type == FW_REG_U32)
                v = v << 16 | ((uint32_t)in[2 * i + 2] << 8 | in[2 * i + 3]);
            v = d->type == FW_REG_I16 ? (uint32_t)(int32_t)(int16_t)(uint16_t)v : v;
            if (pass == 0) {
                FW_VERIFY(regmap_in_range(d, v), FW_ERR_VALUE);
            } else if (pass == 1) {
                fw_err_t e = s_cb->check(d->slot, v);
                if (e != FW_OK)
                    return e;
            } else {
                s_cb->write(d->slot, v);
            }
            i += d->type == FW_REG_U32 ? 2u : 1u;
        }
    }
    /* pass 3: side effects (commands), in address order */
    for (unsigned i = 0; i < qty;) {
        unsigned word;
        const fw_reg_desc_t *d = regmap_find(FW_SPACE_HOLDING, (uint16_t)(addr + i), &word);
        fw_err_t e = s_cb->apply(d->slot, s_cb->read(d->slot));
        if (e != FW_OK)
            return e;
        i += d->type == FW_REG_U32 ? 2u : 1u;
    }
    return FW_OK;
}

/* 43/14 objects: 0 vendor, 1 product code, 2 revision (all "basic"). */
static const char *const k_dev_id[] = {FW_CFG_VENDOR_STR, FW_CFG_PRODUCT_STR, FW_CFG_FW_VERSION_STR};
#define MB_DEV_ID_COUNT 3u

static fw_err_t pdu_device_id(const uint8_t *pdu, size_t len, uint8_t *resp, size_t *rlen)
{
    FW_VERIFY(len >= 2, FW_ERR_VALUE);
    FW_VERIFY(pdu[1] == 0x0E, FW_ERR_FUNCTION); /* only the Read Device ID MEI type */
    FW_VERIFY(len == 4, FW_ERR_VALUE);
    uint8_t code = pdu[2], obj = pdu[3];
    FW_VERIFY(code >= 1 && code <= 4, FW_ERR_VALUE);
    if (code == 4)
        FW_VERIFY(obj < MB_DEV_ID_COUNT, FW_ERR_ADDRESS);
    else if (obj >= MB_DEV_ID_COUNT)
        obj = 0; /* stream access: an unknown start object restarts at 0 (spec 6.21) */
    resp[0] = 0x2B;
    resp[1] = 0x0E;
    resp[2] = code;
    resp[3] = 0x81; /* basic identification, stream and individual access */
    resp[4] = 0x00; /* more follows: all our objects fit in one answer */
    resp[5] = 0x00; /* next object id */
    size_t n = 7;
    uint8_t count = 0;
    unsigned last = code == 4 ? obj : MB_DEV_ID_COUNT - 1u;
    for (unsigned id = obj; id <= last; id++) {
        size_t sl = strlen(k_dev_id[id]);
        resp[n++] = (uint8_t)id;
        resp[n++] = (uint8_t)sl;
        memcpy(&resp[n], k_dev_id[id], sl);
        n += sl;
        count++;
    }
    resp[6] = count;
    *rlen = n;
    return FW_OK;
}

/* Serve one PDU; resp receives the answer PDU. Returns FW_OK or the error to
 * turn into an exception. */
static fw_err_t pdu_serve(const uint8_t *pdu, size_t len, uint8_t *resp, size_t *rlen)
{
    uint8_t fc = pdu[0];
    fw_err_t e;
    switch (fc) {
    case 0x03:
    case 0x04: {
        FW_VERIFY(len == 5, FW_ERR_VALUE);
        uint16_t addr = be16(&pdu[1]), qty = be16(&pdu[3]);
        FW_VERIFY(qty >= 1 && qty <= 125, FW_ERR_VALUE);
        FW_VERIFY((uint32_t)addr + qty <= 0x10000u, FW_ERR_ADDRESS);
        s_cb->refresh();
        e = read_registers(fc == 0x03 ? FW_SPACE_HOLDING : FW_SPACE_INPUT, addr, qty, &resp[2]);
        if (e != FW_OK)
            return e;
        resp[0] = fc;
        resp[1] = (uint8_t)(2u * qty);
        *rlen = 2u + 2u * qty;
        return FW_OK;
    }
    case 0x06: {
        FW_VERIFY(len == 5, FW_ERR_VALUE);
        e = write_registers(be16(&pdu[1]), 1, &pdu[3]);
        if (e != FW_OK)
            return e;
        memcpy(resp, pdu, 5);
        *rlen = 5;
        return FW_OK;
    }
    case 0x10: {
        FW_VERIFY(len >= 6, FW_ERR_VALUE);
        uint16_t addr = be16(&pdu[1]), qty = be16(&pdu[3]);
        FW_VERIFY(qty >= 1 && qty <= 123 && pdu[5] == 2u * qty && len == 6u + 2u * qty,
                  FW_ERR_VALUE);
        FW_VERIFY((uint32_t)addr + qty <= 0x10000u, FW_ERR_ADDRESS);
        e = write_registers(addr, qty, &pdu[6]);
        if (e != FW_OK)
            return e;
        memcpy(resp, pdu, 5);
        *rlen = 5;
        return FW_OK;
    }
    case 0x08: {
        FW_VERIFY(len >= 3, FW_ERR_VALUE);
        FW_VERIFY(be16(&pdu[1]) == 0x0000u, FW_ERR_FUNCTION); /* only "return query data" */
        memcpy(resp, pdu, len);
        *rlen = len;
        return FW_OK;
    }
    case 0x2B:
        return pdu_device_id(pdu, len, resp, rlen);
    default:
        return FW_ERR_FUNCTION;
    }
}

size_t mb_handle_frame(const uint8_t *req, size_t len, uint8_t *resp)
{
    if (len < 4 || len > FW_CFG_MB_MAX_FRAME)
        return 0;
    uint16_t crc = (uint16_t)(req[len - 2] | (uint16_t)req[len - 1] << 8);
    if (mb_crc16(req, len - 2) != crc)
        return 0; /* bad CRC: no answer */
    uint8_t unit = req[0];
    bool broadcast = unit == 0;
    if (!broadcast && unit != FW_CFG_MB_UNIT_ID)
        return 0;
    const uint8_t *pdu = &req[1];
    size_t plen = len - 3;
    if (broadcast && pdu[0] != 0x06 && pdu[0] != 0x10)
        return 0; /* only writes are broadcast */
    s_cb->host_seen();
    size_t rlen = 0;
    fw_err_t e = pdu_serve(pdu, plen, &resp[1], &rlen);
    if (e != FW_OK)
        s_cb->failed(e);
    if (broadcast)
        return 0;
    resp[0] = unit;
    if (e != FW_OK) {
        resp[1] = (uint8_t)(pdu[0] | 0x80u);
        resp[2] = mb_exception_for(e);
        rlen = 2;
    }
    uint16_t c = mb_crc16(resp, rlen + 1u);
    resp[rlen + 1u] = (uint8_t)c;
    resp[rlen + 2u] = (uint8_t)(c >> 8);
    return rlen + 3u;
}

/* ---- framing ------------------------------------------------------------ */
static uint8_t s_rx[FW_CFG_MB_MAX_FRAME];
static uint8_t s_tx[FW_CFG_MB_MAX_FRAME];
static size_t s_rx_len;
static bool s_rx_bad; /* overflow or inner gap > 1.5 characters: discard */
static uint32_t s_t15_us, s_t35_us;

void mb_init(const mb_callbacks_t *cb)
{
    s_cb = cb;
    uint32_t baud = hal_uart_baud();
    s_rx_len = 0;
    s_rx_bad = false;
    if (baud > 19200u || baud == 0) {
        s_t15_us = 750u; /* fixed values above 19200 bit/s (Modbus over serial line 2.5.1.1) */
        s_t35_us = 1750u;
    } else {
        s_t15_us = (uint32_t)(15u * 11u * 1000000u / (10u * baud));
        s_t35_us = (uint32_t)(35u * 11u * 1000000u / (10u * baud));
    }
}

static void frame_done(void)
{
    if (!s_rx_bad) {
        size_t n = mb_handle_frame(s_rx, s_rx_len, s_tx);
        if (n)
            hal_uart_write(s_tx, n);
    }
    s_rx_len = 0;
    s_rx_bad = false;
}

void mb_poll(void)
{
    uint32_t gap;
    int c;
    while ((c = hal_uart_getc(&gap)) >= 0) {
        if (s_rx_len > 0 && gap >= s_t35_us)
            frame_done();
        if (s_rx_len > 0 && gap > s_t15_us && FW_CFG_MB_T15_CHECK)
            s_rx_bad = true;
        if (s_rx_len < sizeof s_rx)
            s_rx[s_rx_len++] = (uint8_t)c;
        else
            s_rx_bad = true;
        if (s_cb->stop())
            return;
    }
    if (s_rx_len > 0 && hal_uart_idle_us() >= s_t35_us)
        frame_done();
}
