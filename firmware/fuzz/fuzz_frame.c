/* fuzz_frame.c - libFuzzer target: frame parsing and register writes.
 *
 * The first byte picks how the rest is delivered to a freshly booted core:
 *   0  one raw frame to mb_handle_frame (CRC as given: mostly rejected)
 *   1  one frame with its CRC appended (reaches the PDU decoder)
 *   2  a session: [len][len bytes] frames to unit 1 with CRC, each followed by
 *      [t] x 4 ms of virtual time (one main-loop pass per 4 ms), so fuzzed
 *      configurations and commands drive the sequencer, safety and flash code
 *      (fuzz_seq.c drives those more finely and checks more)
 *   3  a byte stream through the UART framer: pairs [byte][gap in 10 us]
 * Invariants checked after every step: answers fit 256 bytes and carry a valid
 * CRC, the sink never exceeds the hard current limit, and no LED stays on
 * longer than the hard pulse limit. */
#include <stdlib.h>
#include <string.h>

#include "fw_config.h"
#include "led.h"
#include "mb.h"
#include "hal_test.h"

static void invariants(const uint8_t *resp, size_t n)
{
    if (n > FW_CFG_MB_MAX_FRAME)
        abort();
    if (n) {
        if (n < 5)
            abort();
        uint16_t c = (uint16_t)(resp[n - 2] | resp[n - 1] << 8);
        if (mb_crc16(resp, n - 2) != c)
            abort();
    }
    uint32_t mA = (uint32_t)th.dac * FW_CFG_DAC_FULL_SCALE_MA / FW_CFG_DAC_MAX_CODE;
    if (th.led_ch >= 0 && mA > FW_CFG_HARD_MAX_MA + 1u)
        abort();
    /* the pulse watchdog runs once per main-loop pass */
    if (th.led_ch >= 0 && th.now - led_on_since_us() > FW_CFG_HARD_MAX_PULSE_US + th.poll_us)
        abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t resp[512], frame[300];
    if (size < 1)
        return 0;
    th_fresh();
    uint8_t mode = data[0] % 4u;
    data++;
    size--;
    if (mode == 0) {
        size_t n = mb_handle_frame(data, size, resp);
        invariants(resp, n);
    } else if (mode == 1) {
        if (size > FW_CFG_MB_MAX_FRAME - 2)
            return 0;
        memcpy(frame, data, size);
        size_t n = th_transact_crc(frame, size, resp);
        invariants(resp, n);
    } else if (mode == 2) {
        size_t i = 0;
        th.poll_us = 4000;
        while (i < size) {
            size_t len = data[i++];
            if (len > size - i)
                len = size - i;
            if (len > FW_CFG_MB_MAX_FRAME - 3)
                len = FW_CFG_MB_MAX_FRAME - 3;
            frame[0] = 1;
            memcpy(&frame[1], &data[i], len);
            i += len;
            size_t n = th_transact_crc(frame, len + 1, resp);
            invariants(resp, n);
            if (i < size)
                th_advance((uint64_t)data[i++] * 4000u);
            invariants(resp, 0);
        }
    } else {
        size_t n = 0;
        for (size_t i = 0; i + 1 < size && n < sizeof th.rx; i += 2, n++) {
            th.rx[n] = data[i];
            th.rx_gap[n] = (uint32_t)data[i + 1] * 10u;
        }
        th.rx_len = n;
        th.rx_pos = 0;
        th.idle_us = 4000;
        th.tx_len = 0;
        fw_poll();
        if (th.tx_len > sizeof resp)
            abort();
    }
    return 0;
}
