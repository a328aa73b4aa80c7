/* UART divisor for a clock and baud rate, and the rate error it leaves. Integer macros, so
 * the AVR build checks the budget at compile time (#if) and the host build prints the same
 * numbers (irring-host --baud F_CPU BAUD); evaluate them in #if or in 64-bit arithmetic.
 *
 * An AVR USART divides the clock by 16 (normal) or 8 (U2X) × (UBRR + 1). Normal speed
 * samples each bit more often, so it is used when its error is within the budget; U2X
 * otherwise. At 16 MHz, 115200 baud: normal UBRR 8 is −3.55 %, U2X UBRR 16 is +2.12 %. */
#ifndef IRR_BAUD_H
#define IRR_BAUD_H

/* docs/protocol.md, Link: a device keeps its bit rate within ±2.5 % of nominal. */
#define IRR_BAUD_TOL_PPM 25000

#define IRR_UBRR_AT(f, b, div) (((f) + (div) * (b) / 2) / ((div) * (b)) - 1)
/* the clock that divisor would need for exactly b baud */
#define IRR_CLK_AT(f, b, div) ((div) * (IRR_UBRR_AT(f, b, div) + 1) * (b))
/* |rate error| of a divisor in parts per million of the nominal rate (safe for unsigned
 * F_CPU such as 16000000UL); the sign is + when the clock is faster than needed */
#define IRR_ABS_PPM_AT(f, b, div) \
    (((f) > IRR_CLK_AT(f, b, div) ? (f) - IRR_CLK_AT(f, b, div) \
                                  : IRR_CLK_AT(f, b, div) - (f)) * 1000000 / IRR_CLK_AT(f, b, div))
#define IRR_FAST_AT(f, b, div) ((f) > IRR_CLK_AT(f, b, div))

#define IRR_U2X(f, b) (IRR_ABS_PPM_AT(f, b, 16) > IRR_BAUD_TOL_PPM)
#define IRR_DIV(f, b) (IRR_U2X(f, b) ? 8 : 16)
#define IRR_UBRR(f, b) IRR_UBRR_AT(f, b, IRR_DIV(f, b))
#define IRR_ABS_PPM(f, b) IRR_ABS_PPM_AT(f, b, IRR_DIV(f, b))
#define IRR_BAUD_OK(f, b) (IRR_ABS_PPM(f, b) <= IRR_BAUD_TOL_PPM)

#endif
