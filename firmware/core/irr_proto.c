/* IRR v2 parser and encoder; the checks and their order follow irring/hardware/protocol.py
 * (decode and Decoder), so the C device rejects exactly what the Python reference rejects. */
#include "irr_proto.h"
#include "irr_hal.h"
#ifdef __AVR__
#include <util/crc16.h>
#endif

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
            cmd->framing = IRR_PROTO;
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
        cmd->framing = IRR_PROTO;
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

/* avr-libc's _crc_ccitt_update is the reflected CCITT polynomial (0x8408), the bit order a
 * UART sends (its name is not CRC-16/CCITT-FALSE's, which is _crc_xmodem_update from
 * 0xFFFF). Elsewhere the C that avr-libc documents as its equivalent. */
uint16_t irr_crc16_update(uint16_t crc, uint8_t c)
{
#ifdef __AVR__
    return _crc_ccitt_update(crc, c);
#else
    c ^= (uint8_t)(crc & 0xFF);
    c ^= (uint8_t)(c << 4);
    return (uint16_t)((((uint16_t)c << 8) | (crc >> 8)) ^ (uint8_t)(c >> 4) ^ ((uint16_t)c << 3));
#endif
}

uint16_t irr_crc16(const uint8_t *body, uint8_t n)
{
    uint16_t crc = IRR_CRC_INIT;
    while (n--)
        crc = irr_crc16_update(crc, *body++);
    return (uint16_t)(crc ^ IRR_CRC_XOROUT);
}

static int8_t hex_digit(uint8_t c)
{
    if (c >= '0' && c <= '9')
        return (int8_t)(c - '0');
    if (c >= 'A' && c <= 'F')
        return (int8_t)(c - 'A' + 10);
    return -1;                          /* lower case is not allowed */
}

/* Field kinds of every sentence type, as in irring/hardware/protocol.py (SPEC): the device
 * validates a device-type sentence it receives like any other before answering IRERR 2, so
 * it answers exactly what the reference device answers. */
enum {
    K_ANY = 'a',      /* any 32-bit integer (a motor step) */
    K_SAMPLES = 'n',  /* 1 … 64 */
    K_SETTLE = 's',   /* 0 … 2^31 − 1 */
    K_PROTO = 'p',    /* 1 … 65535 */
    K_NSENS = 'k',    /* 1 … 4096 */
    K_BITS = 'b',     /* 1 … 32 */
    K_MDEG = 'm',     /* 1 … 360000 */
    K_POSITIVE = 'q', /* 1 … 2^31 − 1 */
    K_SEQ = 'e',      /* 0 … 65535 */
    K_DONE = 'd',     /* −1 … 65535 */
    K_U32 = 'u',      /* 0 … 2^32 − 1 (t_ms, counts) */
    K_CODE = 'c',     /* 1 … 99 */
    K_TEXT = 't'
};

typedef struct {
    char name[3];     /* after "IR" */
    uint8_t type;     /* IRR_HLO … for commands, IRR_NONE for device sentences */
    uint8_t min, max; /* field count; the last kind repeats up to max */
    char kinds[10];
} irr_spec_t;

#define SPEC_INF 4
static const IRR_FLASH irr_spec_t specs[] = {
    {{'H', 'L', 'O'}, IRR_HLO, 0, 0, ""},
    {{'S', 'W', 'P'}, IRR_SWP, 4, 4, "aans"},
    {{'G', 'T', 'O'}, IRR_GTO, 1, 1, "a"},
    {{'S', 'T', 'P'}, IRR_STP, 0, 0, ""},
    {{'I', 'N', 'F'}, IRR_NONE, 9, 9, "pkbmqqaat"},
    {{'S', 'C', 'N'}, IRR_NONE, 4, 255, "eauu"},
    {{'D', 'O', 'N'}, IRR_NONE, 1, 1, "d"},
    {{'P', 'O', 'S'}, IRR_NONE, 1, 1, "a"},
    {{'E', 'R', 'R'}, IRR_NONE, 1, 2, "ct"},
};

/* Parse the decimal integer in s[0 … n-1] (optional leading `-`) and check it against
 * `kind`. Returns IRR_OK (value in *out when it fits 32 bits signed), IRR_ERR_SENTENCE (not
 * an integer) or IRR_ERR_ARGUMENT (outside the kind's range). */
static uint8_t parse_field(const uint8_t *s, uint8_t n, uint8_t kind, int32_t *out)
{
    uint8_t neg = 0, i = 0, big = 0;
    uint32_t mag = 0;
    int32_t lo, hi;
    if (n && s[0] == '-') {
        neg = 1;
        i = 1;
    }
    if (i == n)
        return IRR_ERR_SENTENCE;
    for (; i < n; i++) {
        uint8_t d = (uint8_t)(s[i] - '0');
        if (d > 9)
            return IRR_ERR_SENTENCE;
        if (mag > 429496729UL || (mag == 429496729UL && d > 5))
            big = 1;                    /* keep scanning: a later non-digit is still malformed */
        else
            mag = mag * 10 + d;
    }
    if (neg && mag == 0)
        neg = 0;                        /* "-0" is 0 */
    if (big)
        return IRR_ERR_ARGUMENT;
    if (kind == K_U32)
        return neg ? IRR_ERR_ARGUMENT : IRR_OK;
    if (mag > (neg ? 2147483648UL : 2147483647UL))
        return IRR_ERR_ARGUMENT;        /* beyond 32 bits signed: outside every other kind */
    *out = neg ? (int32_t)(0 - mag) : (int32_t)mag;
    switch (kind) {
    case K_SAMPLES: lo = 1; hi = IRR_MAX_SAMPLES; break;
    case K_SETTLE: lo = 0; hi = 2147483647L; break;
    case K_PROTO: lo = 1; hi = 65535L; break;
    case K_NSENS: lo = 1; hi = 4096; break;
    case K_BITS: lo = 1; hi = 32; break;
    case K_MDEG: lo = 1; hi = 360000L; break;
    case K_POSITIVE: lo = 1; hi = 2147483647L; break;
    case K_SEQ: lo = 0; hi = 65535L; break;
    case K_DONE: lo = -1; hi = 65535L; break;
    case K_CODE: lo = 1; hi = 99; break;
    default: return IRR_OK;             /* K_ANY */
    }
    return *out >= lo && *out <= hi ? IRR_OK : IRR_ERR_ARGUMENT;
}

/* Decode one sentence; a v1-framed one (two check digits, all hex) is answered in v1
 * framing: IRHLO with this device's IRINF (its version field tells an old host what it
 * met), anything else with IRERR — this device takes no v1 command. */
static void decode_framed(const uint8_t *line, uint8_t len, irr_cmd_t *cmd);

void irr_decode(const uint8_t *line, uint8_t len, irr_cmd_t *cmd)
{
    cmd->framing = IRR_PROTO;
    decode_framed(line, len, cmd);
    if (cmd->framing == 1 && cmd->error == IRR_OK && cmd->type != IRR_HLO) {
        cmd->type = IRR_NONE;
        cmd->error = IRR_ERR_SENTENCE;
    }
}

static void decode_framed(const uint8_t *line, uint8_t len, irr_cmd_t *cmd)
{
    uint8_t star, i, nf, start, digits, n_specs = sizeof specs / sizeof specs[0];
    uint16_t sent = 0;
    int32_t value = 0, inf_min = 0;
    const IRR_FLASH irr_spec_t *spec = 0;
    cmd->type = IRR_NONE;
    cmd->error = IRR_ERR_SENTENCE;
    if (len < 4 || line[0] != '$' || line[len - 2] != '\r' || line[len - 1] != '\n')
        return;
    for (star = len - 2; star > 0 && line[star] != '*'; star--)
        ;                               /* the last `*` */
    if (star == 0)
        return;                         /* no `*` */
    digits = (uint8_t)(len - 3 - star);
    for (i = 0; i < digits; i++) {
        int8_t d = hex_digit(line[star + 1 + i]);
        if (d < 0 || digits > 4)
            return;                     /* not upper-case hex digits */
        sent = (uint16_t)((sent << 4) | (uint8_t)d);
    }
    if (digits == 2) {
        cmd->framing = 1;               /* an old host's sentence: answered in its framing */
        if (sent != irr_checksum(line + 1, (uint8_t)(star - 1)))
            return;
    } else if (digits != 4 || sent != irr_crc16(line + 1, (uint8_t)(star - 1))) {
        return;
    }
    for (i = 1; i < star; i++)
        if (line[i] < 0x20 || line[i] > 0x7E || line[i] == '$' || line[i] == '*')
            return;
    /* type: 5 upper-case letters starting with IR */
    if (star < 6 || (star > 6 && line[6] != ',') || line[1] != 'I' || line[2] != 'R')
        return;
    for (i = 3; i < 6; i++)
        if (line[i] < 'A' || line[i] > 'Z')
            return;
    for (i = 0; i < n_specs; i++)
        if (specs[i].name[0] == line[3] && specs[i].name[1] == line[4] &&
            specs[i].name[2] == line[5])
            spec = &specs[i];
    if (!spec) {
        cmd->error = IRR_ERR_TYPE;
        return;
    }
    nf = star > 6 ? 1 : 0;              /* count the fields: one after each `,` */
    for (i = 7; i < star; i++)
        if (line[i] == ',')
            nf++;
    if (nf < spec->min || nf > spec->max)
        return;
    start = 7;
    for (i = 0; i < nf; i++) {          /* field by field, in order, like the reference */
        uint8_t end = start, e = IRR_OK, k = 0, kind;
        while (spec->kinds[k + 1] && k < i)
            k++;                        /* the last kind repeats */
        kind = (uint8_t)spec->kinds[k];
        while (end < star && line[end] != ',')
            end++;
        if (kind != K_TEXT)
            e = parse_field(line + start, (uint8_t)(end - start), kind, &value);
        if (e != IRR_OK) {
            cmd->error = e;
            return;
        }
        if (i < 4)
            cmd->arg[i] = value;
        if (i == 6)
            inf_min = value;
        if (i == 7 && spec == &specs[SPEC_INF] && inf_min > value) {
            cmd->error = IRR_ERR_ARGUMENT;  /* IRINF with min_step > max_step */
            return;
        }
        start = (uint8_t)(end + 1);
    }
    if (spec->type == IRR_NONE) {
        cmd->error = IRR_ERR_TYPE;      /* a well-formed device sentence: not a command */
        return;
    }
    cmd->type = spec->type;
    cmd->error = IRR_OK;
}

/* ------------------------------------------------------------------ encoder */

static uint8_t out_cs, out_framing = IRR_PROTO;
static uint16_t out_crc;

static void out_byte(uint8_t c)
{
    out_cs ^= c;
    out_crc = irr_crc16_update(out_crc, c);
    hal_putc(c);
}

void irr_out_framing(uint8_t version)
{
    out_framing = version;
}

void irr_out_begin(uint8_t type)
{
    uint8_t i;
    hal_putc('$');
    out_cs = 0;
    out_crc = IRR_CRC_INIT;
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
    uint16_t crc = (uint16_t)(out_crc ^ IRR_CRC_XOROUT);
    int8_t shift = 12;
    hal_putc('*');
    if (out_framing == 1) {
        crc = out_cs;
        shift = 4;
    }
    for (; shift >= 0; shift -= 4)
        hal_putc((uint8_t)hex[(crc >> shift) & 15]);
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
