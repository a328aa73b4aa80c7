/* The synthetic room of the host build and the simavr board: ADC counts as a function of
 * (motor step, sensor), documented in firmware/README.md ("Host build") and checked by
 * tests/test_firmware.py. One home for both harnesses. */
#ifndef IRR_SYNTHETIC_H
#define IRR_SYNTHETIC_H

#include <stdint.h>
#include "irr_config.h"

static inline uint16_t irr_synthetic_count(int32_t step, uint8_t sensor)
{
    return (uint16_t)(400 + 97 * sensor + 7 * (step - IRR_MIN_STEP));
}

#endif
