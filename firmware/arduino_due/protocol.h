/* Host <-> arm-controller wire protocol, plain C (no Arduino headers) so it builds with the
 * host's gcc for tests. Mirrors hw_bridge/protocol.py; layouts in docs/protocol.md.
 * Frame: COBS(type u8 | payload | crc16 u16le) 0x00, crc = CRC-16/CCITT-FALSE. Little-endian. */
#ifndef HW_PROTOCOL_H
#define HW_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define PROTO_VERSION 1
#define PROTO_MAX_MOTORS 32
#define PROTO_MAX_DECODED (1 + 18 + 8 * PROTO_MAX_MOTORS + 2)
#define PROTO_MAX_ENCODED (PROTO_MAX_DECODED + PROTO_MAX_DECODED / 254 + 1)

enum {
  MSG_HELLO = 0x01, MSG_ARM = 0x02, MSG_DISARM = 0x03, MSG_DEMAND = 0x10,
  MSG_STATE = 0x11, MSG_CONFIG = 0x20, MSG_CONFIG_ACK = 0x21
};
enum { ST_ARMED = 0x01, ST_WATCHDOG_TRIPPED = 0x02, ST_ESTOP = 0x04, ST_FAULT = 0x08 };
enum { STATE_HAS_VELOCITIES = 0x01, TELEMETRY_VELOCITIES = 0x01 };
enum { DEC_OK = 0, DEC_CRC, DEC_COBS, DEC_LENGTH, DEC_UNKNOWN_TYPE };

typedef struct {
  uint8_t type;
  union {
    struct { uint8_t version, n_motors; uint16_t watchdog_ms; } hello;
    struct { uint32_t seq; uint8_t flags; uint32_t mask; uint8_t n; int32_t counts[PROTO_MAX_MOTORS]; } demand;
    struct {
      uint32_t seq, ack_seq, mcu_time_us; uint16_t status, rx_errors; uint8_t n, flags;
      int32_t positions[PROTO_MAX_MOTORS]; int32_t velocities[PROTO_MAX_MOTORS];
    } state;
    struct { uint16_t config_id, watchdog_ms; uint8_t telemetry; int32_t max_speed; } config;
    struct { uint16_t config_id; uint8_t result; } config_ack;
  } u;
} proto_msg_t;

typedef struct {
  uint32_t frames, crc_errors, cobs_errors, length_errors, unknown_type, overflow;
} proto_stats_t;

typedef struct {
  uint8_t buf[PROTO_MAX_ENCODED];
  size_t len;
  int overflowing;
  proto_stats_t stats;
} proto_decoder_t;

uint16_t proto_crc16(const uint8_t *data, size_t len);
size_t proto_cobs_encode(const uint8_t *in, size_t len, uint8_t *out);
/* Returns decoded length, or (size_t)-1 on malformed input. */
size_t proto_cobs_decode(const uint8_t *in, size_t len, uint8_t *out);
/* Encodes a complete frame including the 0x00 delimiter into out (>= PROTO_MAX_ENCODED + 1
 * bytes). Returns its length, or 0 if msg is invalid. */
size_t proto_encode(const proto_msg_t *msg, uint8_t *out);
/* Decodes one frame (without delimiter); returns DEC_OK or an error kind. */
int proto_decode_frame(const uint8_t *frame, size_t len, proto_msg_t *msg);
void proto_decoder_init(proto_decoder_t *d);
/* Feeds one byte; returns 1 and fills msg when a valid frame completes, else 0. Never fails. */
int proto_decoder_push(proto_decoder_t *d, uint8_t byte, proto_msg_t *msg);
uint32_t proto_bad_frames(const proto_stats_t *s);
/* 1 if u32 seq comes after last (RFC 1982). */
int proto_seq_newer(uint32_t seq, uint32_t last);

#ifdef __cplusplus
}
#endif
#endif
