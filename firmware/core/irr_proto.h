/* IRR v1 sentences (docs/protocol.md): a byte-at-a-time parser of host commands and an
 * encoder that streams device sentences through hal_putc, checksumming on the fly.
 * Plain C99, no board headers: the same file runs on the AVR and on the host. */
#ifndef IRR_PROTO_H
#define IRR_PROTO_H

#include <stdint.h>
#include "irr_config.h"

/* IRERR codes (docs/protocol.md) */
enum { IRR_OK = 0, IRR_ERR_SENTENCE = 1, IRR_ERR_TYPE = 2, IRR_ERR_ARGUMENT = 3,
       IRR_ERR_RANGE = 4, IRR_ERR_BUSY = 5 };

/* host → device sentence types */
enum { IRR_NONE = 0, IRR_HLO, IRR_SWP, IRR_GTO, IRR_STP };

typedef struct {
    uint8_t error;      /* IRR_OK, or the IRERR code the device answers with */
    uint8_t type;       /* IRR_HLO … IRR_STP when error == IRR_OK */
    int32_t arg[4];     /* fields in order (IRSWP: from, to, samples, settle_ms) */
} irr_cmd_t;

typedef struct {
    uint8_t buf[IRR_MAX_SENTENCE];  /* `$` … up to the byte before `\n` */
    uint8_t len;
    uint8_t in_sentence;
    uint8_t overflow;               /* discarding the rest of a too-long sentence */
} irr_parser_t;

void irr_parser_reset(irr_parser_t *p);

/* Feed one received byte. Returns 1 when a sentence ended (or was cut short by a `$`, or
 * grew past 128 bytes): *cmd then holds the command or the IRERR code to answer. Bytes
 * outside sentences are ignored (returns 0). */
uint8_t irr_parse_byte(irr_parser_t *p, uint8_t c, irr_cmd_t *cmd);

/* Decode one whole sentence `$` … `\n` (len bytes) into *cmd (sets cmd->error). */
void irr_decode(const uint8_t *line, uint8_t len, irr_cmd_t *cmd);

/* XOR of n bytes (the bytes between `$` and `*`). */
uint8_t irr_checksum(const uint8_t *body, uint8_t n);

/* device → host sentence types */
enum { IRR_INF, IRR_SCN, IRR_DON, IRR_POS, IRR_ERR };

/* Encoder: irr_out_begin(IRR_SCN), then fields, then irr_out_end() (`*CS\r\n`). */
void irr_out_begin(uint8_t type);
void irr_out_int(int32_t v);
void irr_out_uint(uint32_t v);
void irr_out_text(const IRR_FLASH char *s);
void irr_out_end(void);

/* Whole replies. */
void irr_send_error(uint8_t code);

#endif
