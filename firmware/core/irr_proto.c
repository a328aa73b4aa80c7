/* IRR v1 parser and encoder; the checks and their order follow irring/hardware/protocol.py
 * (decode and Decoder), so the C device rejects exactly what the Python reference rejects. */
#include "irr_proto.h"
#include "irr_hal.h"

static const IRR_FLASH char e0[] = "", e1[] = "bad sentence", e2[] = "unknown type",
    e3[] = "bad argument", e4[] = "step out of range", e5[] = "busy";
static const IRR_FLASH char *const IRR_FLASH error_text[] = {e0, e1, e2, e3, e4, e5};
static const IRR_FLASH char out_types[][4] = {"INF", "SCN", "DON", "POS", "ERR"};

void irr_parser_reset(irr_parser_t *p)
{
    p->len = 0;
    p->in_sentence = 0;
    p->overflow = 0;
}

uint8_t irr_parse_byte(irr_parser_t *p, uint8_t c, irr_cmd_t *cmd)
{
    if (!p->in_sentence) {
        if (c == '$') {
            p->buf[0] = '$';
            p->len = 1;
            p->in_sentence = 1;
            p->overflow = 0;
        }
        return 0;                       /* line noise between sentences */
    }
    if (c == '$') {                     /* a new sentence cuts the current one short */
        uint8_t cut = !p->overflow;
        p->buf[0] = '$';
        p->len = 1;
        p->overflow = 0;
        if (cut) {
            cmd->error = IRR_ERR_SENTENCE;
            cmd->type = IRR_NONE;
            return 1;
        }
        return 0;
    }
    if (c == '\n') {
        uint8_t was_overflow = p->overflow;
        p->in_sentence = 0;
        p->overflow = 0;
        if (was_overflow)
            return 0;                   /* already answered when it grew too long */
        p->buf[p->len] = '\n';          /* len < IRR_MAX_SENTENCE here: room for it */
        irr_decode(p->buf, (uint8_t)(p->len + 1), cmd);
        return 1;
    }
    if (p->overflow)
        return 0;
    p->buf[p->len++] = c;
    if (p->len >= IRR_MAX_SENTENCE) {   /* no room left for `\n`: too long */
        p->overflow = 1;
        cmd->error = IRR_ERR_SENTENCE;
        cmd->type = IRR_NONE;
        return 1;
    }
    return 0;
}

uint8_t irr_checksum(const uint8_t *body, uint8_t n)
{
    uint8_t cs = 0;
    while (n--)
        cs ^= *body++;
    return cs;
}

static int8_t hex_digit(uint8_t c)
{
    if (c >= '0' && c <= '9')
        return (int8_t)(c - '0');
    if (c >= 'A' && c <= 'F')
        return (int8_t)(c - 'A' + 10);
    return -1;                          /* lower case is not allowed */
}

/* Parse the decimal integer in s[0 … n-1] (optional leading `-`). Returns IRR_OK,
 * IRR_ERR_SENTENCE (not an integer) or IRR_ERR_ARGUMENT (outside int32). */
static uint8_t parse_int(const uint8_t *s, uint8_t n, int32_t *out)
{
    uint8_t neg = 0, i = 0, big = 0;
    uint32_t mag = 0;
    if (n && s[0] == '-') {
        neg = 1;
        i = 1;
    }
    if (i == n)
        return IRR_ERR_SENTENCE;
    for (; i < n; i++) {
        if (s[i] < '0' || s[i] > '9')
            return IRR_ERR_SENTENCE;
        if (mag > 214748364UL || (mag == 214748364UL && (uint8_t)(s[i] - '0') > 8))
            big = 1;                    /* keep scanning: a later non-digit is still malformed */
        else
            mag = mag * 10 + (uint8_t)(s[i] - '0');
    }
    if (big || mag > (neg ? 2147483648UL : 2147483647UL))
        return IRR_ERR_ARGUMENT;
    *out = neg ? (int32_t)(0 - mag) : (int32_t)mag;
    return IRR_OK;
}

void irr_decode(const uint8_t *line, uint8_t len, irr_cmd_t *cmd)
{
    uint8_t star, i, nf, want, start;
    int8_t hi, lo;
    cmd->type = IRR_NONE;
    cmd->error = IRR_ERR_SENTENCE;
    if (len < 4 || line[0] != '$' || line[len - 2] != '\r' || line[len - 1] != '\n')
        return;
    for (star = len - 2; star > 0 && line[star] != '*'; star--)
        ;                               /* the last `*` */
    if (star == 0 || len - 2 - star != 3)
        return;                         /* no `*`, or not two checksum digits */
    hi = hex_digit(line[star + 1]);
    lo = hex_digit(line[star + 2]);
    if (hi < 0 || lo < 0)
        return;
    if ((uint8_t)((hi << 4) | lo) != irr_checksum(line + 1, (uint8_t)(star - 1)))
        return;
    for (i = 1; i < star; i++)
        if (line[i] < 0x20 || line[i] > 0x7E || line[i] == '$' || line[i] == '*')
            return;
    /* type: 5 upper-case letters starting with IR */
    if (star < 6 || (star > 6 && line[6] != ',') || line[1] != 'I' || line[2] != 'R')
        return;
    for (i = 3; i < 6; i++)
        if (line[i] < 'A' || line[i] > 'Z')
            return;
    if (line[3] == 'H' && line[4] == 'L' && line[5] == 'O') {
        cmd->type = IRR_HLO;
        want = 0;
    } else if (line[3] == 'S' && line[4] == 'W' && line[5] == 'P') {
        cmd->type = IRR_SWP;
        want = 4;
    } else if (line[3] == 'G' && line[4] == 'T' && line[5] == 'O') {
        cmd->type = IRR_GTO;
        want = 1;
    } else if (line[3] == 'S' && line[4] == 'T' && line[5] == 'P') {
        cmd->type = IRR_STP;
        want = 0;
    } else {                            /* device sentences are not commands either */
        cmd->error = IRR_ERR_TYPE;
        return;
    }
    nf = 0;                             /* count the fields: one per `,` */
    for (i = 6; i < star; i++)
        if (line[i] == ',')
            nf++;
    if (nf != want) {
        cmd->type = IRR_NONE;
        return;
    }
    start = 7;
    for (nf = 0; nf < want; nf++) {     /* field by field, in order, like the reference */
        uint8_t end = start, e;
        while (end < star && line[end] != ',')
            end++;
        e = parse_int(line + start, (uint8_t)(end - start), &cmd->arg[nf]);
        if (e == IRR_OK && cmd->type == IRR_SWP) {
            if (nf == 2 && (cmd->arg[2] < 1 || cmd->arg[2] > IRR_MAX_SAMPLES))
                e = IRR_ERR_ARGUMENT;
            if (nf == 3 && cmd->arg[3] < 0)
                e = IRR_ERR_ARGUMENT;
        }
        if (e != IRR_OK) {
            cmd->type = IRR_NONE;
            cmd->error = e;
            return;
        }
        start = (uint8_t)(end + 1);
    }
    cmd->error = IRR_OK;
}

/* ------------------------------------------------------------------ encoder */

static uint8_t out_cs;

static void out_byte(uint8_t c)
{
    out_cs ^= c;
    hal_putc(c);
}

void irr_out_begin(uint8_t type)
{
    uint8_t i;
    hal_putc('$');
    out_cs = 0;
    out_byte('I');
    out_byte('R');
    for (i = 0; i < 3; i++)
        out_byte((uint8_t)out_types[type][i]);
}

/* Decimal digits by subtracting powers of ten: an AVR has no divider, and a 32-bit
 * division per digit cost each IRSCN ~1 ms of the ATmega328P's time (measured in simavr). */
static const IRR_FLASH uint32_t pow10[] = {1000000000UL, 100000000UL, 10000000UL, 1000000UL,
                                           100000UL, 10000UL, 1000UL, 100UL, 10UL};

static void out_digits(uint32_t v)
{
    uint8_t i, started = 0;
    for (i = 0; i < sizeof pow10 / sizeof pow10[0]; i++) {
        uint32_t p = pow10[i];
        uint8_t d = 0;
        while (v >= p) {
            v -= p;
            d++;
        }
        if (d || started) {
            out_byte((uint8_t)('0' + d));
            started = 1;
        }
    }
    out_byte((uint8_t)('0' + v));
}

void irr_out_uint(uint32_t v)
{
    out_byte(',');
    out_digits(v);
}

void irr_out_int(int32_t v)
{
    if (v < 0) {
        out_byte(',');
        out_byte('-');
        out_digits(0u - (uint32_t)v);
    } else {
        irr_out_uint((uint32_t)v);
    }
}

void irr_out_text(const IRR_FLASH char *s)
{
    out_byte(',');
    while (*s)
        out_byte((uint8_t)*s++);
}

void irr_out_end(void)
{
    static const IRR_FLASH char hex[] = "0123456789ABCDEF";
    uint8_t cs = out_cs;
    hal_putc('*');
    hal_putc((uint8_t)hex[cs >> 4]);
    hal_putc((uint8_t)hex[cs & 15]);
    hal_putc('\r');
    hal_putc('\n');
}

void irr_send_error(uint8_t code)
{
    irr_out_begin(IRR_ERR);
    irr_out_int(code);
    irr_out_text(error_text[code]);
    irr_out_end();
}
