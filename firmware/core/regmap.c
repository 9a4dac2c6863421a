/* regmap.c - the register map: address lookup, ranges, defaults. */
#define FW_REGISTERS_IMPL
#include "regmap.h"

#include <stddef.h>

#if FW_GENERATOR_VERSION != 1
#error "fw_registers.h comes from another generator version: run make generate"
#endif

const fw_reg_desc_t *regmap_table(fw_reg_space_t space, unsigned *n)
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
    const fw_reg_desc_t *t = regmap_table(space, &n);
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

const fw_reg_desc_t *regmap_find(fw_reg_space_t space, uint16_t addr, unsigned *word)
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

bool regmap_in_range(const fw_reg_desc_t *d, uint32_t v)
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

uint32_t regmap_default(const fw_reg_desc_t *d)
{
    if (d->type == FW_REG_U32 && d->def == -1)
        return UINT32_MAX;
    return d->type == FW_REG_I16 ? (uint32_t)(int32_t)(int16_t)d->def : (uint32_t)d->def;
}
