/* What this ring is: the numbers IRINF reports, and the firmware's timing.
 * One home for them on the C side; the Python side's are irring.designs.PAPER_RING and
 * irring.scenario (tests/test_firmware.py checks that IRINF matches them). */
#ifndef IRR_CONFIG_H
#define IRR_CONFIG_H

#define IRR_PROTO          2       /* protocol version: IRINF reports it */
#define IRR_SENSORS        12      /* ir_00 … ir_11, two per MCP3202 */
#define IRR_ADC_BITS       12      /* MCP3202 */
#define IRR_STEP_MDEG      1800    /* motor full step, millidegrees */
#define IRR_GEAR_NUM       3       /* sensors turn 3/5 of the motor (belt), 1.08° per step */
#define IRR_GEAR_DEN       5
#define IRR_MIN_STEP       (-35)   /* ±35 steps = ±37.8° at the sensors */
#define IRR_MAX_STEP       35
#define IRR_MAX_SAMPLES    64

#ifndef IRR_FIRMWARE
#define IRR_FIRMWARE       "irring-fw-2.0"
#endif

/* A GP2D12 updates its output every 38.3 ms (datasheet, ±9.6 ms): each sample waits one
 * period so that it is a fresh measurement taken where the sensor now points. */
#define IRR_SAMPLE_PERIOD_MS 39
/* Time per motor step: 500 full steps/s keeps an A4988-driven NEMA 17 well inside its
 * pull-in torque with the ring's inertia (the emulator assumes the same, 2 ms). */
#define IRR_STEP_MS          2

#define IRR_MAX_SENTENCE   128     /* bytes from `$` to `\n` inclusive */

/* Where constant text lives. A Harvard MCU would copy it into RAM at start-up; the AVR
 * build defines IRR_FLASH=__flash (GNU C named address space, no header needed) so the
 * texts stay in flash: the ATmega8535 has only 512 B of RAM. */
#ifndef IRR_FLASH
#define IRR_FLASH
#endif

#endif
