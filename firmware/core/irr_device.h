/* The ring's firmware proper: answers IRR v2 commands and runs sweeps as a non-blocking
 * state machine (so IRSTP and IRHLO are heard mid-sweep). Board I/O goes through irr_hal.h.
 *
 *   irr_init();
 *   for (;;) { while (byte available) irr_receive(byte); irr_poll(); }
 */
#ifndef IRR_DEVICE_H
#define IRR_DEVICE_H

#include <stdint.h>

void irr_init(void);
void irr_receive(uint8_t c);
/* Advance motion and sampling to hal_millis(); returns the ms until it next has work
 * (0: call again at once; 0xFFFFFFFF: idle, nothing scheduled). */
uint32_t irr_poll(void);
/* The motor step the ring is at (the last step commanded and timed out). */
int32_t irr_position(void);

#endif
