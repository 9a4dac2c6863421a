/* trig.h - camera lines (shutter, focus), flash-sync capture, button debounce. */
#ifndef FACETTE_TRIG_H
#define FACETTE_TRIG_H

#include <stdbool.h>
#include <stdint.h>

void trig_init(void);
void trig_shutter(bool active);
void trig_focus(bool active);
void trig_sync_flush(void);
/* Earliest sync edge at or after t_from; true if one was captured. */
bool trig_sync_seen(uint64_t t_from, uint64_t *t_edge);
/* Debounced button: returns true once per press. */
bool trig_button_pressed(void);

#endif
