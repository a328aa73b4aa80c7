/* irring-simavr: the AVR image itself, run in simavr, on a pseudo-terminal.
 *
 *   irring-simavr --link ring.pty build/irring-atmega328p.elf
 *
 * A simulated board around the simulated MCU: six MCP3202 on the SPI bus, selected by
 * PC0 … PC5 as wired in firmware/README.md, answering the synthetic counts of
 * host/irr_synthetic.h for the step a simulated stepper is at; the stepper counts rising
 * STEP edges (PD2) in the direction DIR (PD3) gives while /ENABLE (PD4) is low. The UART's
 * bytes go to and from a pty. So the test drives the very hex file one flashes, through
 * its UART, SPI and STEP/DIR code, with SerialRing. Needs libsimavr-dev. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_spi.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

#include "irr_synthetic.h"

static avr_t *avr;
static avr_irq_t *spi_in, *uart_in;
static uint8_t portc = 0x3F, step_pin, dir_pin, nenable = 1;
static int32_t motor;
static uint8_t spi_byte, spi_channel;   /* position in the 3-byte MCP3202 frame */
static int xon = 1;
static uint8_t out[1 << 16];
static size_t out_len;
static volatile sig_atomic_t stopping;

static int selected_chip(void)
{
    int chip = -1;
    for (int c = 0; c < 6; c++)
        if (!(portc & (1 << c))) {
            if (chip >= 0)
                return -2;              /* two chips selected: bus contention */
            chip = c;
        }
    return chip;
}

static void on_portc(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    portc = (uint8_t)value;
    spi_byte = 0;                       /* any /CS change starts a new frame */
}

static void on_pin(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    int pin = (int)(intptr_t)param;
    if (pin == 2) {
        if (value && !step_pin && !nenable)
            motor += dir_pin ? 1 : -1;  /* a driver steps on STEP's rising edge */
        step_pin = (uint8_t)value;
    } else if (pin == 3) {
        dir_pin = (uint8_t)value;
    } else if (pin == 4) {
        nenable = (uint8_t)value;
    }
}

/* MCP3202: byte 0 carries the start bit, byte 1 SGL/ODD/MSBF (reply: null bit + B11-B8),
 * byte 2 is don't-care (reply: B7-B0). */
static void on_spi(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    int chip = selected_chip();
    uint8_t reply = 0xFF;               /* nobody drives MISO: it floats high */
    if (chip >= 0) {
        uint16_t count = irr_synthetic_count(motor, (uint8_t)(2 * chip + spi_channel));
        if (spi_byte == 0) {
            reply = 0;
        } else if (spi_byte == 1) {
            spi_channel = (value >> 6) & 1;
            count = irr_synthetic_count(motor, (uint8_t)(2 * chip + spi_channel));
            reply = (value & 0xA0) == 0xA0 ? (uint8_t)(count >> 8) : 0xFF;
        } else {
            reply = (uint8_t)count;
        }
        spi_byte++;
    }
    avr_raise_irq(spi_in, reply);
}

static void on_uart_out(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    if (out_len < sizeof out)
        out[out_len++] = (uint8_t)value;
}

static void on_xon(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)value; (void)param;
    xon = 1;
}

static void on_xoff(avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)value; (void)param;
    xon = 0;
}

static void on_signal(int sig)
{
    (void)sig;
    stopping = 1;
}

int main(int argc, char **argv)
{
    const char *link = NULL, *image = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--link") && i + 1 < argc)
            link = argv[++i];
        else if (argv[i][0] != '-' && !image)
            image = argv[i];
        else {
            fprintf(stderr, "usage: irring-simavr --link PATH IMAGE.elf\n");
            return 2;
        }
    }
    if (!link || !image) {
        fprintf(stderr, "usage: irring-simavr --link PATH IMAGE.elf\n");
        return 2;
    }
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(image, &fw) != 0) {
        fprintf(stderr, "irring-simavr: cannot read %s\n", image);
        return 2;
    }
    if (!fw.mmcu[0])
        strcpy(fw.mmcu, "atmega328p");
    if (!fw.frequency)
        fw.frequency = 16000000;
    avr = avr_make_mcu_by_name(fw.mmcu);
    if (!avr) {
        fprintf(stderr, "irring-simavr: simavr has no core %s\n", fw.mmcu);
        return 2;
    }
    avr_init(avr);
    avr_load_firmware(avr, &fw);
    avr->log = LOG_ERROR;

    uint32_t flags = 0;                 /* bytes go to the pty, not to stdout */
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~AVR_UART_FLAG_STDIO;
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            on_uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                            on_xon, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                            on_xoff, NULL);
    spi_in = avr_io_getirq(avr, AVR_IOCTL_SPI_GETIRQ(0), SPI_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_SPI_GETIRQ(0), SPI_IRQ_OUTPUT),
                            on_spi, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('C'), IOPORT_IRQ_PIN_ALL),
                            on_portc, NULL);
    for (intptr_t pin = 2; pin <= 4; pin++)
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), (int)pin),
                                on_pin, (void *)pin);

    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) < 0 || unlockpt(master) < 0) {
        perror("irring-simavr: pty");
        return 1;
    }
    char slave_name[128];
    snprintf(slave_name, sizeof slave_name, "%s", ptsname(master));
    int slave = open(slave_name, O_RDWR | O_NOCTTY);   /* held open: no hang-ups */
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    unlink(link);
    if (symlink(slave_name, link) < 0) {
        fprintf(stderr, "irring-simavr: cannot link %s: %s\n", link, strerror(errno));
        return 2;
    }
    printf("irring-simavr: %s at %u Hz serving on %s linked at %s\n", fw.mmcu,
           (unsigned)fw.frequency, slave_name, link);
    fflush(stdout);
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);

    uint8_t in[256];
    size_t in_len = 0, in_done = 0;
    int state = cpu_Running;
    while (!stopping && state != cpu_Done && state != cpu_Crashed) {
        for (int i = 0; i < 2000 && state != cpu_Done && state != cpu_Crashed; i++)
            state = avr_run(avr);
        if (in_done == in_len) {
            ssize_t n = read(master, in, sizeof in);
            in_len = n > 0 ? (size_t)n : 0;
            in_done = 0;
        }
        while (in_done < in_len && xon)
            avr_raise_irq(uart_in, in[in_done++]);   /* simavr paces them at the baud rate */
        if (out_len) {
            ssize_t n = write(master, out, out_len);
            if (n > 0) {
                memmove(out, out + n, out_len - (size_t)n);
                out_len -= (size_t)n;
            }
        }
    }
    if (state == cpu_Crashed)
        fprintf(stderr, "irring-simavr: the AVR crashed at pc 0x%04x\n", avr->pc);
    char target[128];
    ssize_t n = readlink(link, target, sizeof target - 1);
    if (n > 0 && (target[n] = 0, !strcmp(target, slave_name)))
        unlink(link);
    close(slave);
    close(master);
    return state == cpu_Crashed ? 1 : 0;
}
