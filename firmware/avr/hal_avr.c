/* AVR HAL and main loop: ATmega328P (default) or ATmega8535 (the paper's MCU).
 *
 *   UART  PD0 RXD, PD1 TXD: 8N1 at BAUD, interrupt-driven ring buffers both ways
 *   SPI   MOSI/MISO/SCK to six MCP3202, chip selects PC0 … PC5 (active low), 1 MHz, mode 0
 *         MCP3202 #c channel 0 is sensor ir_(2c), channel 1 is ir_(2c+1)
 *   motor PD2 STEP, PD3 DIR (high: counter-clockwise seen from above), PD4 /ENABLE
 *   clock Timer0 compare match every 1 ms: hal_millis(), t_ms, settle and sample waits
 * Wiring table and board notes: firmware/README.md. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>
#include <util/delay.h>

#include "irr_baud.h"
#include "irr_device.h"
#include "irr_hal.h"

#ifndef F_CPU
#error "F_CPU (Hz) must be given, e.g. -DF_CPU=16000000 (the Makefile does)"
#endif
#ifndef BAUD
#define BAUD 115200
#endif
#if !IRR_BAUD_OK(F_CPU, BAUD)
#error "UART baud rate error: this F_CPU cannot make BAUD within the protocol's +-2.5 % (try irring-host --baud F_CPU BAUD; 14745600 Hz is exact)"
#endif
#if IRR_U2X(F_CPU, BAUD)
#define UART_U2X 1
#define UART_UBRR IRR_UBRR_AT(F_CPU, BAUD, 8)
#else
#define UART_U2X 0
#define UART_UBRR IRR_UBRR_AT(F_CPU, BAUD, 16)
#endif
#define TICK_OCR (F_CPU / 64 / 1000 - 1)   /* Timer0, clk/64, 1 kHz */
#if TICK_OCR > 255
#error "Timer0 cannot tick at 1 kHz with clk/64 at this F_CPU"
#endif

#if defined(__AVR_ATmega328P__) || defined(__AVR_ATmega328__) || defined(__AVR_ATmega168__)
#define SPI_DDR DDRB
#define SPI_SS PB2
#define SPI_MOSI PB3
#define SPI_SCK PB5
#define UART_UBRRH UBRR0H
#define UART_UBRRL UBRR0L
#define UART_UCSRA UCSR0A
#define UART_UCSRB UCSR0B
#define UART_UDR UDR0
#define UART_U2X_BIT U2X0
#define UART_RXEN RXEN0
#define UART_TXEN TXEN0
#define UART_RXCIE RXCIE0
#define UART_UDRIE UDRIE0
#define UART_SET_8N1() (UCSR0C = (1 << UCSZ01) | (1 << UCSZ00))
#define TICK_VECT TIMER0_COMPA_vect
#define TICK_SETUP()                                  \
    do {                                              \
        TCCR0A = 1 << WGM01;                          \
        OCR0A = TICK_OCR;                             \
        TIMSK0 = 1 << OCIE0A;                         \
        TCCR0B = (1 << CS01) | (1 << CS00);           \
    } while (0)
#elif defined(__AVR_ATmega8535__) || defined(__AVR_ATmega16__) || defined(__AVR_ATmega32__)
#define SPI_DDR DDRB
#define SPI_SS PB4
#define SPI_MOSI PB5
#define SPI_SCK PB7
#define UART_UBRRH UBRRH
#define UART_UBRRL UBRRL
#define UART_UCSRA UCSRA
#define UART_UCSRB UCSRB
#define UART_UDR UDR
#define UART_U2X_BIT U2X
#define UART_RXEN RXEN
#define UART_TXEN TXEN
#define UART_RXCIE RXCIE
#define UART_UDRIE UDRIE
#define UART_SET_8N1() (UCSRC = (1 << URSEL) | (1 << UCSZ1) | (1 << UCSZ0))
#define TICK_VECT TIMER0_COMP_vect
#define TICK_SETUP()                                           \
    do {                                                       \
        OCR0 = TICK_OCR;                                       \
        TIMSK |= 1 << OCIE0;                                   \
        TCCR0 = (1 << WGM01) | (1 << CS01) | (1 << CS00);      \
    } while (0)
#else
#error "unsupported MCU: add its register names to avr/hal_avr.c"
#endif

#define MOTOR_STEP PD2
#define MOTOR_DIR PD3
#define MOTOR_NENABLE PD4

/* ------------------------------------------------------------------ clock */

static volatile uint32_t ticks_ms;

ISR(TICK_VECT)
{
    ticks_ms++;
}

uint32_t hal_millis(void)
{
    uint32_t t;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { t = ticks_ms; }
    return t;
}

/* ------------------------------------------------------------------ UART */

#ifndef RX_SIZE
#define RX_SIZE 32   /* powers of two, ≤ 256; an IRSCN (≤ 93 bytes) is queued in pieces */
#endif
#ifndef TX_SIZE
#define TX_SIZE 64
#endif
static volatile uint8_t rx_buf[RX_SIZE], tx_buf[TX_SIZE];
static volatile uint8_t rx_head, rx_tail, tx_head, tx_tail;

ISR(USART_RX_vect)
{
    uint8_t c = UART_UDR;
    uint8_t next = (uint8_t)((rx_head + 1) & (RX_SIZE - 1));
    if (next != rx_tail) {  /* full: the byte is lost; the parser's checks catch it */
        rx_buf[rx_head] = c;
        rx_head = next;
    }
}

ISR(USART_UDRE_vect)
{
    if (tx_head == tx_tail) {
        UART_UCSRB &= (uint8_t)~(1 << UART_UDRIE);
        return;
    }
    UART_UDR = tx_buf[tx_tail];
    tx_tail = (uint8_t)((tx_tail + 1) & (TX_SIZE - 1));
}

void hal_putc(uint8_t c)
{
    uint8_t next = (uint8_t)((tx_head + 1) & (TX_SIZE - 1));
    while (next == tx_tail)
        ;                      /* full: the UDRE interrupt drains it */
    tx_buf[tx_head] = c;
    tx_head = next;
    UART_UCSRB |= 1 << UART_UDRIE;
}

static int16_t uart_getc(void)
{
    uint8_t c;
    if (rx_head == rx_tail)
        return -1;
    c = rx_buf[rx_tail];
    rx_tail = (uint8_t)((rx_tail + 1) & (RX_SIZE - 1));
    return c;
}

static void uart_init(void)
{
    UART_UBRRH = (uint8_t)(UART_UBRR >> 8);
    UART_UBRRL = (uint8_t)UART_UBRR;
#if UART_U2X
    UART_UCSRA = 1 << UART_U2X_BIT;
#else
    UART_UCSRA = 0;
#endif
    UART_SET_8N1();
    UART_UCSRB = (1 << UART_RXEN) | (1 << UART_TXEN) | (1 << UART_RXCIE);
}

/* ------------------------------------------------------------------ SPI and MCP3202 */

static void spi_init(void)
{
    /* SS stays an output (high) so the SPI stays master; the ADCs use PC0 … PC5 */
    SPI_DDR |= (1 << SPI_SS) | (1 << SPI_MOSI) | (1 << SPI_SCK);
    PORTB |= 1 << SPI_SS;
    PORTC |= 0x3F;            /* all chip selects high (idle) before they become outputs */
    DDRC |= 0x3F;
    SPCR = (1 << SPE) | (1 << MSTR) | (1 << SPR0);  /* mode 0, F_CPU/16 = 1 MHz */
}

static uint8_t spi_transfer(uint8_t out)
{
    SPDR = out;
    while (!(SPSR & (1 << SPIF)))
        ;
    return SPDR;
}

/* One single-ended conversion of MCP3202 `chip`, channel `ch` (datasheet fig. 6-1: start
 * bit, then SGL/DIFF = 1, ODD/SIGN = ch, MSBF = 1; 12 bits come back MSB first). */
static uint16_t mcp3202_read(uint8_t chip, uint8_t ch)
{
    uint8_t hi, lo;
    PORTC &= (uint8_t)~(1 << chip);
    spi_transfer(0x01);
    hi = spi_transfer((uint8_t)(0xA0 | (ch << 6)));
    lo = spi_transfer(0x00);
    PORTC |= (uint8_t)(1 << chip);
    return (uint16_t)(((hi & 0x0F) << 8) | lo);
}

void hal_read_sensors(uint8_t sample, uint16_t counts[IRR_SENSORS])
{
    uint8_t k;
    (void)sample;
    for (k = 0; k < IRR_SENSORS; k++)
        counts[k] = mcp3202_read((uint8_t)(k >> 1), (uint8_t)(k & 1));
}

/* ------------------------------------------------------------------ stepper driver */

static void motor_init(void)
{
    PORTD |= 1 << MOTOR_NENABLE;                 /* disabled until irr_init says so */
    PORTD &= (uint8_t)~((1 << MOTOR_STEP) | (1 << MOTOR_DIR));
    DDRD |= (1 << MOTOR_STEP) | (1 << MOTOR_DIR) | (1 << MOTOR_NENABLE);
}

void hal_motor_enable(uint8_t on)
{
    if (on)
        PORTD &= (uint8_t)~(1 << MOTOR_NENABLE);
    else
        PORTD |= 1 << MOTOR_NENABLE;
}

void hal_motor_step(int8_t dir)
{
#ifdef IRR_DIR_INVERT
    dir = (int8_t)-dir;
#endif
    if (dir > 0)
        PORTD |= 1 << MOTOR_DIR;
    else
        PORTD &= (uint8_t)~(1 << MOTOR_DIR);
    _delay_us(1);             /* A4988: DIR set-up 200 ns; DRV8825: 650 ns */
    PORTD |= 1 << MOTOR_STEP;
    _delay_us(2);             /* STEP high ≥ 1 µs (A4988), ≥ 1.9 µs (DRV8825) */
    PORTD &= (uint8_t)~(1 << MOTOR_STEP);
}

/* ------------------------------------------------------------------ main */

int main(void)
{
    int16_t c;
    motor_init();
    spi_init();
    uart_init();
    TICK_SETUP();
    sei();
    irr_init();
    for (;;) {
        while ((c = uart_getc()) >= 0)
            irr_receive((uint8_t)c);
        irr_poll();
    }
}
