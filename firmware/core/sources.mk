# Portable core sources and include paths, relative to firmware/.
# Used by firmware/Makefile and by every port's build (ports/stm32f4/Makefile).
# One file per module; who may call whom: firmware/README.md, "Firmware core".
CORE_SRCS := core/fw.c core/mb.c core/regmap.c core/regs.c core/seq.c core/led.c \
             core/trig.c core/safe.c core/nvm.c core/fw_assert.c
CORE_INCLUDES := include hal core
