/* irring-host: the firmware core on a pseudo-terminal, for tests and for trying the host
 * side without a board.
 *
 *   irring-host --link ring.pty [--speed 20]   serve on a pty, symlinked at ./ring.pty
 *   irring-host --stdio                           commands on stdin, answers on stdout
 *   irring-host --baud F_CPU BAUD                 print the UART divisor and its rate error
 *   irring-host --crc TEXT                        print the v2 CRC of TEXT (4 hex digits)
 *
 * Host HAL: the clock is the monotonic clock × --speed (the device's t_ms, settle and
 * sample waits run that much faster than wall time); the motor is a counter; sensor k at
 * motor step s, sample j reads irr_synthetic_count(s, k) + (0, −1, +1, −1, … )[j], a dither
 * that averages (rounded half up) back to exactly irr_synthetic_count(s, k) for every sample
 * count but leaves the last sample off by one: a device that forgot to average shows. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "irr_baud.h"
#include "irr_device.h"
#include "irr_proto.h"
#include "irr_hal.h"
#include "irr_synthetic.h"


/* ------------------------------------------------------------------ host HAL */

static double speed = 1.0;
static struct timespec t0;
static int32_t motor;                /* the "motor": steps from power-up */
static uint8_t enabled;
static unsigned char out[1 << 16];   /* bytes the device sent, not yet written */
static size_t out_len;

uint32_t hal_millis(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    double ms = ((double)(t.tv_sec - t0.tv_sec) * 1e3 + (double)(t.tv_nsec - t0.tv_nsec) / 1e6);
    return (uint32_t)(unsigned long long)(ms * speed);
}

void hal_putc(uint8_t c)
{
    if (out_len < sizeof out)
        out[out_len++] = c;
}

void hal_motor_enable(uint8_t on)
{
    enabled = on;
}

void hal_motor_step(int8_t dir)
{
    if (enabled)                     /* a disabled driver ignores STEP */
        motor += dir;
}

void hal_read_sensors(uint8_t sample, uint16_t counts[IRR_SENSORS])
{
    int dither = sample == 0 ? 0 : (sample % 2 ? -1 : 1);
    for (uint8_t k = 0; k < IRR_SENSORS; k++)
        counts[k] = (uint16_t)(irr_synthetic_count(motor, k) + dither);
}

/* ------------------------------------------------------------------ serving */

static volatile sig_atomic_t stopping;
static const char *link_path;
static char slave_name[128];

static void on_signal(int sig)
{
    (void)sig;
    stopping = 1;
}

static void unlink_ours(void)
{
    char target[sizeof slave_name];
    ssize_t n;
    if (!link_path)
        return;
    n = readlink(link_path, target, sizeof target - 1);
    if (n > 0) {
        target[n] = 0;
        if (strcmp(target, slave_name) == 0)
            unlink(link_path);
    }
}

/* Write what the device produced; returns -1 when the peer is gone for good. */
static int flush_out(int fd)
{
    size_t done = 0;
    while (done < out_len) {
        ssize_t n = write(fd, out + done, out_len - done);
        if (n < 0) {
            if (errno == EAGAIN || errno == EINTR)
                break;
            return -1;
        }
        done += (size_t)n;
    }
    memmove(out, out + done, out_len - done);
    out_len -= done;
    return 0;
}

static int serve(int in_fd, int out_fd, int exit_at_eof)
{
    unsigned char buf[512];
    int eof = 0;
    while (!stopping) {
        uint32_t wait = irr_poll();
        if (wait == 0)
            continue;                /* more work due now */
        if (flush_out(out_fd) < 0)
            return 1;
        if (eof && wait == 0xFFFFFFFFUL && out_len == 0)
            return 0;                /* --stdio: input ended and the device is idle */
        /* sleep until the device's next deadline (device ms / speed), at most 5 ms */
        double wall_ms = wait == 0xFFFFFFFFUL ? 5.0 : (double)wait / speed;
        if (wall_ms > 5.0)
            wall_ms = 5.0;
        struct timespec ts = {0, (long)(wall_ms * 1e6)};
        struct pollfd pf[2] = {{in_fd, eof ? 0 : POLLIN, 0}, {out_fd, POLLOUT, 0}};
        int n = ppoll(pf, out_len ? 2 : 1, &ts, NULL);
        if (n < 0 && errno != EINTR)
            return 1;
        if (n > 0 && (pf[0].revents & (POLLIN | POLLHUP))) {
            ssize_t got = read(in_fd, buf, sizeof buf);
            if (got > 0) {
                for (ssize_t i = 0; i < got; i++)
                    irr_receive(buf[i]);
            } else if (got == 0 || (errno != EAGAIN && errno != EINTR && errno != EIO)) {
                if (exit_at_eof)
                    eof = 1;
            } else if (errno == EIO) {
                usleep(2000);        /* pty: no host has the slave open right now */
            }
        }
    }
    return 0;
}

static int serve_pty(void)
{
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) < 0 || unlockpt(master) < 0) {
        perror("irring-host: cannot create a pseudo-terminal");
        return 1;
    }
    snprintf(slave_name, sizeof slave_name, "%s", ptsname(master));
    /* hold the slave open ourselves: the master then never sees a hang-up between hosts */
    int slave = open(slave_name, O_RDWR | O_NOCTTY);
    struct termios tio;
    if (slave < 0 || tcgetattr(slave, &tio) < 0) {
        perror("irring-host: cannot open the pty slave");
        return 1;
    }
    cfmakeraw(&tio);                 /* no echo, no CR/LF translation */
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    if (link_path) {
        unlink(link_path);
        if (symlink(slave_name, link_path) < 0) {
            fprintf(stderr, "irring-host: cannot link %s -> %s: %s\n", link_path, slave_name,
                    strerror(errno));
            return 2;
        }
    }
    printf("irring-host: serving IRR v%d on %s%s%s (speed %g)\n", IRR_PROTO, slave_name,
           link_path ? " linked at " : "", link_path ? link_path : "", speed);
    fflush(stdout);
    int rc = serve(master, master, 0);
    unlink_ours();
    close(slave);
    close(master);
    return rc;
}

static int baud_report(const char *f_text, const char *b_text)
{
    unsigned long long f = strtoull(f_text, NULL, 10), b = strtoull(b_text, NULL, 10);
    if (f == 0 || b == 0 || b * 8 > f) {
        fprintf(stderr, "irring-host: --baud needs F_CPU and BAUD in Hz, F_CPU ≥ 8 × BAUD\n");
        return 2;
    }
    unsigned long long div = IRR_DIV(f, b), ubrr = IRR_UBRR(f, b);
    printf("f_cpu=%llu baud=%llu u2x=%d ubrr=%llu actual=%.1f error_ppm=%s%llu ok=%d\n", f, b,
           (int)IRR_U2X(f, b), ubrr, (double)f / (double)(div * (ubrr + 1)),
           IRR_FAST_AT(f, b, div) || IRR_ABS_PPM(f, b) == 0 ? "+" : "-", IRR_ABS_PPM(f, b), (int)IRR_BAUD_OK(f, b));
    return IRR_BAUD_OK(f, b) ? 0 : 1;
}

static int usage(FILE *to, int rc)
{
    fprintf(to,
            "usage: irring-host --link PATH [--speed X]   serve the firmware on a pty at PATH\n"
            "       irring-host --stdio [--speed X]       commands on stdin, answers on stdout\n"
            "       irring-host --baud F_CPU BAUD          UART divisor and rate error\n"
            "       irring-host --crc TEXT                 the protocol's CRC-16 of TEXT\n"
            "--speed X runs the device clock X times faster than wall time (default 1).\n"
            "Sensor k at motor step s reads 400 + 97 k + 7 (s + 35) counts.\n");
    return rc;
}

int main(int argc, char **argv)
{
    int stdio_mode = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--link") && i + 1 < argc) {
            link_path = argv[++i];
        } else if (!strcmp(argv[i], "--speed") && i + 1 < argc) {
            char *end;
            speed = strtod(argv[++i], &end);
            if (*end || !(speed > 0)) {
                fprintf(stderr, "irring-host: --speed %s: expected a number > 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(argv[i], "--stdio")) {
            stdio_mode = 1;
        } else if (!strcmp(argv[i], "--baud") && i + 2 < argc) {
            return baud_report(argv[i + 1], argv[i + 2]);
        } else if (!strcmp(argv[i], "--crc") && i + 1 < argc) {
            size_t n = strlen(argv[i + 1]);
            if (n > 255) {
                fprintf(stderr, "irring-host: --crc takes at most 255 bytes\n");
                return 2;
            }
            printf("%04X\n", irr_crc16((const uint8_t *)argv[i + 1], (uint8_t)n));
            return 0;
        } else if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            return usage(stdout, 0);
        } else {
            fprintf(stderr, "irring-host: unknown or incomplete argument %s\n", argv[i]);
            return usage(stderr, 2);
        }
    }
    if (!stdio_mode && !link_path)
        return usage(stderr, 2);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    clock_gettime(CLOCK_MONOTONIC, &t0);
    irr_init();
    if (stdio_mode)
        return serve(STDIN_FILENO, STDOUT_FILENO, 1);
    return serve_pty();
}
