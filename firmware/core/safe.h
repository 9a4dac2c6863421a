/* safe.h - latched faults and their log, temperature derating, the current and
 * pulse limits (clamped here and nowhere else), host watchdog, hardware
 * watchdog. safe.c calls no module above it: what a fault does to the lights,
 * camera lines and sequencer is done by the hook fw.c registers. */
#ifndef FACETTE_SAFE_H
#define FACETTE_SAFE_H

#include <stdbool.h>
#include <stdint.h>

/* What a latched fault asks of the rest of the firmware. */
typedef enum {
    SAFE_KEEP_GOING = 0, /* logged only (watchdog reset, calibration invalid) */
    SAFE_LIGHT_OFF,      /* light off and manual channel -1 (host silent) */
    SAFE_STOP,           /* blocking: also camera lines off, sequencer to FAULT */
} safe_action_t;

typedef struct {
    /* The one fault hook: called inside the critical section after a fault is
     * latched and logged, with what it asks for. */
    void (*on_fault)(safe_action_t action);
    /* What the supervisor watches, read afresh at each check. */
    int (*lit_channel)(void);       /* -1: no light on */
    uint64_t (*lit_since_us)(void); /* when that channel was switched on */
    bool (*scan_active)(void);      /* ARMED, RUNNING or PAUSED */
} safe_hooks_t;

/* Start supervising; hooks (kept, not copied) must have every member set.
 * Latches WATCHDOG_RESET after a watchdog reset. */
void safe_init(const safe_hooks_t *hooks);
void safe_poll(void); /* sample, check limits and watchdogs, kick the watchdog */
/* Latch fault code (FW_FAULT_*), log it with detail, and hand it to the hook
 * (SAFE_STOP when the fault is blocking). */
void safe_fault(unsigned code, uint16_t detail);
bool safe_blocking_fault(void);
void safe_clear(void);
bool safe_derating(void);
void safe_host_seen(void); /* a request reached us: feeds the host watchdog */
/* max_current_mA and max_pulse_us as configured, clamped to the hard limits
 * (FW_CFG_HARD_MAX_MA, FW_CFG_HARD_MAX_PULSE_US). */
uint32_t safe_max_current_mA(void);
uint32_t safe_max_pulse_us(void);

#endif
