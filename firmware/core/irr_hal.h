/* What the portable core needs from a board. Implemented by avr/hal_avr.c (the real ring)
 * and host/irring_host.c (a pseudo-terminal with synthetic counts). */
#ifndef IRR_HAL_H
#define IRR_HAL_H

#include <stdint.h>
#include "irr_config.h"

/* Milliseconds since power-up; wraps at 2^32 like IRSCN's t_ms. */
uint32_t hal_millis(void);

/* Queue one byte for the UART; blocks only while the transmit buffer is full. */
void hal_putc(uint8_t c);

/* Driver ENABLE: nonzero energises the coils (holding torque). */
void hal_motor_enable(uint8_t on);

/* One full-step pulse; dir > 0 turns the ring counter-clockwise seen from above. */
void hal_motor_step(int8_t dir);

/* Read every sensor once (sample index `sample` of the current step, 0 first) into
 * counts[0 … IRR_SENSORS-1], sensor 0 first; each 0 … 2^IRR_ADC_BITS − 1. */
void hal_read_sensors(uint8_t sample, uint16_t counts[IRR_SENSORS]);

#endif
