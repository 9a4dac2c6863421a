/* regs.c - the device's state, one value slot per register. */
#include "regs.h"

#include "fw_err.h"
#include "regmap.h"

static uint32_t s_val[FW_SLOT_COUNT];

void regs_init(void)
{
    for (unsigned s = 0; s < 2; s++) {
        unsigned n;
        const fw_reg_desc_t *t = regmap_table((fw_reg_space_t)s, &n);
        for (unsigned i = 0; i < n; i++)
            s_val[t[i].slot] = regmap_default(&t[i]);
    }
}

uint32_t regs_get(unsigned slot)
{
    FW_ASSERT(slot < FW_SLOT_COUNT);
    return s_val[slot];
}

int32_t regs_get_i(unsigned slot)
{
    return (int32_t)regs_get(slot);
}

void regs_set(unsigned slot, uint32_t value)
{
    FW_ASSERT(slot < FW_SLOT_COUNT);
    s_val[slot] = value;
}
