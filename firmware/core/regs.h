/* regs.h - the device's state: one value per register slot (FW_SLOT_* in
 * fw_registers.h). Every module keeps what the host may read or write here;
 * Modbus reaches it only through fw.c. */
#ifndef FACETTE_REGS_H
#define FACETTE_REGS_H

#include <stdint.h>

void regs_init(void);                        /* every slot to its register's default */
uint32_t regs_get(unsigned slot);            /* raw value (i16 sign-extended) */
int32_t regs_get_i(unsigned slot);           /* the same, signed */
void regs_set(unsigned slot, uint32_t value); /* no range check: the caller's value */

#endif
