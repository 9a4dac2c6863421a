# Portable core sources and include paths, relative to firmware/.
# Used by firmware/Makefile and by every port's build (ports/stm32f4/Makefile).
CORE_SRCS := core/fw.c core/mb.c core/mb_regs.c core/seq.c core/led.c core/trig.c \
             core/safe.c core/nvm.c
CORE_INCLUDES := include hal core
