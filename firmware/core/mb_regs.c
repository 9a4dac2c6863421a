/* mb_regs.c - the register store: values, lookup, range validation. */
#define FW_REGISTERS_IMPL
#include "fw_core.h"

#if FW_GENERATOR_VERSION != 1
#error "fw_registers.h comes from another generator version: run make generate"
#endif

static uint32_t s_val[FW_SLOT_COUNT];

static const fw_reg_desc_t *table_of(fw_reg_space_t space, unsigned *n)
{
    if (space == FW_SPACE_INPUT) {
        *n = FW_REG_INPUT_COUNT;
        return fw_reg_input_table;
    }
    *n = FW_REG_HOLDING_COUNT;
    return fw_reg_holding_table;
}

static const fw_reg_desc_t *find(fw_reg_space_t space, uint16_t addr)
{
    unsigned n;
    const fw_reg_desc_t *t = table_of(space, &n);
    unsigned lo = 0, hi = n;
    while (lo < hi) {
        unsigned mid = (lo + hi) / 2u;
        if (t[mid].addr == addr)
            return &t[mid];
        if (t[mid].addr < addr)
            lo = mid + 1u;
        else
            hi = mid;
    }
    return NULL;
}

/* Descriptor covering addr and which word of it (0 high, 1 low for u32). */
static const fw_reg_desc_t *find_word(fw_reg_space_t space, uint16_t addr, unsigned *word)
{
    const fw_reg_desc_t *d = find(space, addr);
    if (d) {
        *word = 0;
        return d;
    }
    if (addr > 0) {
        d = find(space, (uint16_t)(addr - 1u));
        if (d && d->type == FW_REG_U32) {
            *word = 1;
            return d;
        }
    }
    return NULL;
}

static uint32_t store_value(uint8_t type, int32_t v)
{
    return type == FW_REG_I16 ? (uint32_t)(int32_t)(int16_t)v : (uint32_t)v;
}

void mb_reg_init(void)
{
    for (unsigned s = 0; s < 2; s++) {
        unsigned n;
        const fw_reg_desc_t *t = table_of((fw_reg_space_t)s, &n);
        for (unsigned i = 0; i < n; i++)
            s_val[t[i].slot] = t[i].type == FW_REG_U32 && t[i].def == -1
                                   ? UINT32_MAX
                                   : store_value(t[i].type, t[i].def);
    }
}

uint32_t mb_reg_get(unsigned slot)
{
    FW_ASSERT(slot < FW_SLOT_COUNT);
    return s_val[slot];
}

int32_t mb_reg_get_i(unsigned slot)
{
    return (int32_t)mb_reg_get(slot);
}

void mb_reg_set(unsigned slot, uint32_t value)
{
    FW_ASSERT(slot < FW_SLOT_COUNT);
    s_val[slot] = value;
}

fw_err_t mb_reg_read(fw_reg_space_t space, uint16_t addr, uint16_t qty, uint8_t *out)
{
    FW_VERIFY((uint32_t)addr + qty <= 0x10000u, FW_ERR_ADDRESS);
    for (unsigned i = 0; i < qty; i++) {
        unsigned word;
        if (!find_word(space, (uint16_t)(addr + i), &word))
            return FW_ERR_ADDRESS;
    }
    for (unsigned i = 0; i < qty; i++) {
        unsigned word;
        const fw_reg_desc_t *d = find_word(space, (uint16_t)(addr + i), &word);
        uint32_t v = s_val[d->slot];
        uint16_t w = d->type == FW_REG_U32 ? (uint16_t)(word == 0 ? v >> 16 : v) : (uint16_t)v;
        out[2 * i] = (uint8_t)(w >> 8);
        out[2 * i + 1] = (uint8_t)w;
    }
    return FW_OK;
}

static bool in_range(const fw_reg_desc_t *d, uint32_t v)
{
    switch (d->type) {
    case FW_REG_I16: {
        int32_t s = (int16_t)(uint16_t)v;
        return s >= d->min && s <= d->max;
    }
    case FW_REG_U32:
        return v >= (uint32_t)d->min && (d->max == -1 || v <= (uint32_t)d->max);
    default:
        return (int32_t)v >= d->min && (int32_t)v <= d->max;
    }
}

fw_err_t mb_reg_write(uint16_t addr, uint16_t qty, const uint8_t *in)
{
    FW_VERIFY((uint32_t)addr + qty <= 0x10000u, FW_ERR_ADDRESS);
    /* pass 1: addresses exist and every u32 is written whole */
    for (unsigned i = 0; i < qty;) {
        unsigned word;
        const fw_reg_desc_t *d = find_word(FW_SPACE_HOLDING, (uint16_t)(addr + i), &word);
        FW_VERIFY(d != NULL, FW_ERR_ADDRESS);
        if (d->type == FW_REG_U32) {
            FW_VERIFY(word == 0 && i + 1u < qty, FW_ERR_ADDRESS);
            i += 2;
        } else {
            i += 1;
        }
    }
    /* pass 2: ranges, then the application's own checks (state, lock) */
    for (int pass = 0; pass < 3; pass++) {
        for (unsigned i = 0; i < qty;) {
            unsigned word;
            const fw_reg_desc_t *d = find_word(FW_SPACE_HOLDING, (uint16_t)(addr + i), &word);
            uint32_t v = (uint32_t)in[2 * i] << 8 | in[2 * i + 1];
            if (d->type == FW_REG_U32)
                v = v << 16 | ((uint32_t)in[2 * i + 2] << 8 | in[2 * i + 3]);
            v = d->type == FW_REG_I16 ? (uint32_t)(int32_t)(int16_t)(uint16_t)v : v;
            if (pass == 0) {
                FW_VERIFY(in_range(d, v), FW_ERR_VALUE);
            } else if (pass == 1) {
                fw_err_t e = fw_reg_check(d->slot, v);
                if (e != FW_OK)
                    return e;
            } else {
                s_val[d->slot] = v;
            }
            i += d->type == FW_REG_U32 ? 2u : 1u;
        }
    }
    /* pass 3: side effects (commands), in address order */
    for (unsigned i = 0; i < qty;) {
        unsigned word;
        const fw_reg_desc_t *d = find_word(FW_SPACE_HOLDING, (uint16_t)(addr + i), &word);
        fw_err_t e = fw_reg_apply(d->slot, s_val[d->slot]);
        if (e != FW_OK)
            return e;
        i += d->type == FW_REG_U32 ? 2u : 1u;
    }
    return FW_OK;
}
