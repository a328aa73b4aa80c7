/* Sweep state machine. Per sweep step: one motor step (IRR_STEP_MS), settle_ms, then
 * `samples` reads of all sensors each one GP2 period apart, averaged (rounded half up);
 * then IRSCN with the clock at the last read. Semantics follow the reference device
 * (irring/hardware/emulator.py Device): IRHLO and IRSTP are answered at any time, IRSTP
 * ends a sweep (not an IRGTO) with IRDON of the last seq sent; IRSWP/IRGTO while a sweep or
 * move runs get IRERR 5; range checks (IRERR 4) follow the field checks (IRERR 1/3). */
#include "irr_device.h"
#include "irr_hal.h"
#include "irr_proto.h"

enum { IDLE, GOTO, SWP_MOVE, SWP_SETTLE, SWP_SAMPLE };

static struct {
    irr_parser_t parser;
    uint32_t sums[IRR_SENSORS];
    uint32_t due;          /* hal_millis() at which the current wait ends */
    uint32_t settle_ms;
    int16_t pos;           /* motor step the ring is at */
    int16_t target;        /* where the current move ends */
    int16_t to;            /* a sweep's last step */
    int8_t dir;            /* a sweep's direction, ±1 */
    uint8_t state;
    uint8_t samples, k;
    uint16_t seq;          /* seq of the last IRSCN sent */
    uint8_t any_sent;      /* 0 until the first IRSCN (IRDON then reports −1) */
} d;

void irr_init(void)
{
    irr_parser_reset(&d.parser);
    d.state = IDLE;
    d.pos = 0;             /* power up with the sensors radial: step 0 */
    d.any_sent = 0;
    hal_motor_enable(1);   /* hold the ring where it is */
}

int32_t irr_position(void)
{
    return d.pos;
}

static const IRR_FLASH char firmware_name[] = IRR_FIRMWARE;

static void send_info(void)
{
    irr_out_begin(IRR_INF);
    irr_out_int(IRR_PROTO);
    irr_out_int(IRR_SENSORS);
    irr_out_int(IRR_ADC_BITS);
    irr_out_int(IRR_STEP_MDEG);
    irr_out_int(IRR_GEAR_NUM);
    irr_out_int(IRR_GEAR_DEN);
    irr_out_int(IRR_MIN_STEP);
    irr_out_int(IRR_MAX_STEP);
    irr_out_text(firmware_name);
    irr_out_end();
}

static void send_done(void)
{
    irr_out_begin(IRR_DON);
    irr_out_int(d.any_sent ? (int32_t)d.seq : -1);
    irr_out_end();
}

static void send_position(void)
{
    irr_out_begin(IRR_POS);
    irr_out_int(d.pos);
    irr_out_end();
}

static void answer(const irr_cmd_t *c);

static uint8_t in_range(int32_t step)
{
    return step >= IRR_MIN_STEP && step <= IRR_MAX_STEP;
}

static void handle(const irr_cmd_t *c)
{
    irr_out_framing(c->framing);   /* this answer only; a sweep's sentences are v2 */
    answer(c);
    irr_out_framing(IRR_PROTO);
}

static void answer(const irr_cmd_t *c)
{
    if (c->error) {
        irr_send_error(c->error);
        return;
    }
    switch (c->type) {
    case IRR_HLO:
        send_info();
        return;
    case IRR_STP:
        if (d.state >= SWP_MOVE)
            d.state = IDLE;    /* the step in progress is abandoned, never reported */
        send_done();
        return;
    default:
        break;
    }
    if (d.state != IDLE) {
        irr_send_error(IRR_ERR_BUSY);
        return;
    }
    if (c->type == IRR_GTO) {
        if (!in_range(c->arg[0])) {
            irr_send_error(IRR_ERR_RANGE);
            return;
        }
        d.target = (int16_t)c->arg[0];
        d.state = GOTO;
    } else {                   /* IRR_SWP */
        if (!in_range(c->arg[0]) || !in_range(c->arg[1])) {
            irr_send_error(IRR_ERR_RANGE);
            return;
        }
        d.target = (int16_t)c->arg[0];
        d.to = (int16_t)c->arg[1];
        d.dir = d.to >= d.target ? 1 : -1;
        d.samples = (uint8_t)c->arg[2];
        d.settle_ms = (uint32_t)c->arg[3];
        d.state = SWP_MOVE;
    }
    d.due = hal_millis();      /* start moving at once */
}

void irr_receive(uint8_t c)
{
    irr_cmd_t cmd;
    if (irr_parse_byte(&d.parser, c, &cmd))
        handle(&cmd);
}

static uint8_t reached(uint32_t now, uint32_t due)
{
    return (int32_t)(now - due) >= 0;  /* wrap-safe */
}

static void send_scan(uint32_t now)
{
    uint8_t i;
    uint8_t half = d.samples / 2;
    d.seq = d.any_sent ? (uint16_t)(d.seq + 1) : 0;
    d.any_sent = 1;
    irr_out_begin(IRR_SCN);
    irr_out_uint(d.seq);
    irr_out_int(d.pos);
    irr_out_uint(now);
    for (i = 0; i < IRR_SENSORS; i++)
        irr_out_uint((d.sums[i] + half) / d.samples);
    irr_out_end();
}

uint32_t irr_poll(void)
{
    uint32_t now = hal_millis();
    uint8_t i;
    uint16_t counts[IRR_SENSORS];

    if (d.state == IDLE)
        return 0xFFFFFFFFUL;
    if (!reached(now, d.due))
        return d.due - now;
    switch (d.state) {
    case GOTO:
    case SWP_MOVE:
        if (d.pos != d.target) {       /* one step, then give the motor IRR_STEP_MS */
            int8_t dir = d.target > d.pos ? 1 : -1;
            hal_motor_step(dir);
            d.pos = (int16_t)(d.pos + dir);
            d.due = now + IRR_STEP_MS;
        } else if (d.state == GOTO) {
            d.state = IDLE;
            send_position();
        } else {
            d.state = SWP_SETTLE;
            d.due = now + d.settle_ms;
        }
        break;
    case SWP_SETTLE:
        for (i = 0; i < IRR_SENSORS; i++)
            d.sums[i] = 0;
        d.k = 0;
        d.state = SWP_SAMPLE;
        d.due = now + IRR_SAMPLE_PERIOD_MS;
        break;
    case SWP_SAMPLE:
        hal_read_sensors(d.k, counts);
        for (i = 0; i < IRR_SENSORS; i++)
            d.sums[i] += counts[i];
        if (++d.k < d.samples) {
            d.due = now + IRR_SAMPLE_PERIOD_MS;
            break;
        }
        send_scan(now);
        if (d.pos == d.to) {
            d.state = IDLE;
            send_done();
        } else {
            d.target = (int16_t)(d.pos + d.dir);
            d.state = SWP_MOVE;
            d.due = now;
        }
        break;
    }
    return 0;
}
