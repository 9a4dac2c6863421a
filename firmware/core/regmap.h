/* regmap.h - the register map: which register addresses exist, their type,
 * range and default, and the value slot each one lives in (the tables come from
 * protocol/registers.toml through include/fw_registers.h). No values here: they
 * are in regs.c. */
#ifndef FACETTE_REGMAP_H
#define FACETTE_REGMAP_H

#include <stdbool.h>
#include <stdint.h>

#include "fw_registers.h"

/* Every descriptor of a space, sorted by address; *n receives their count. */
const fw_reg_desc_t *regmap_table(fw_reg_space_t space, unsigned *n);
/* Descriptor covering register addr and which word of it (*word 0 = the only or
 * high word, 1 = the low word of a u32), or NULL when addr is not in the space. */
const fw_reg_desc_t *regmap_find(fw_reg_space_t space, uint16_t addr, unsigned *word);
/* v (as stored: i16 sign-extended) lies within the register's min..max. */
bool regmap_in_range(const fw_reg_desc_t *d, uint32_t v);
/* The register's default value as stored. */
uint32_t regmap_default(const fw_reg_desc_t *d);

#endif
