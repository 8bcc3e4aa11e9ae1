/* Wire protocol core for the Arduino Due firmware (see protocol.h). No allocation, no I/O. */
#include "protocol.h"

#include <string.h>

uint16_t proto_crc16(const uint8_t *data, size_t len) {
  uint16_t crc = 0xFFFF;
  for (size_t i = 0; i < len; i++) {
    crc ^= (uint16_t)data[i] << 8;
    for (int b = 0; b < 8; b++) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
  }
  return crc;
}

size_t proto_cobs_encode(const uint8_t *in, size_t len, uint8_t *out) {
  size_t code_idx = 0, o = 1;
  uint8_t code = 1;
  for (size_t i = 0; i < len; i++) {
    if (in[i] == 0) {
      out[code_idx] = code; code_idx = o++; code = 1;
    } else {
      out[o++] = in[i]; code++;
      if (code == 0xFF) {
        out[code_idx] = code;
        if (i + 1 == len) return o; /* a run of 254 at the very end needs no trailing code */
        code_idx = o++; code = 1;
      }
    }
  }
  out[code_idx] = code;
  return o;
}

size_t proto_cobs_decode(const uint8_t *in, size_t len, uint8_t *out) {
  size_t i = 0, o = 0;
  while (i < len) {
    uint8_t code = in[i];
    if (code == 0 || i + code > len) return (size_t)-1;
    for (size_t k = i + 1; k < i + code; k++) {
      if (in[k] == 0) return (size_t)-1;
      out[o++] = in[k];
    }
    i += code;
    if (code < 0xFF && i < len) out[o++] = 0;
  }
  return o;
}

static void put16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { put16(p, (uint16_t)v); put16(p + 2, (uint16_t)(v >> 16)); }
static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static uint32_t get32(const uint8_t *p) { return (uint32_t)get16(p) | ((uint32_t)get16(p + 2) << 16); }

static int popcount32(uint32_t v) { int n = 0; while (v) { n += (int)(v & 1u); v >>= 1; } return n; }

size_t proto_encode(const proto_msg_t *m, uint8_t *out) {
  uint8_t body[PROTO_MAX_DECODED];
  size_t n = 0;
  body[n++] = m->type;
  switch (m->type) {
    case MSG_HELLO:
      body[n++] = m->u.hello.version; body[n++] = m->u.hello.n_motors;
      put16(body + n, m->u.hello.watchdog_ms); n += 2; break;
    case MSG_ARM: case MSG_DISARM: break;
    case MSG_DEMAND:
      if (m->u.demand.n > PROTO_MAX_MOTORS || popcount32(m->u.demand.mask) != m->u.demand.n) return 0;
      put32(body + n, m->u.demand.seq); n += 4; body[n++] = m->u.demand.flags;
      put32(body + n, m->u.demand.mask); n += 4;
      for (int i = 0; i < m->u.demand.n; i++) { put32(body + n, (uint32_t)m->u.demand.counts[i]); n += 4; }
      break;
    case MSG_STATE:
      if (m->u.state.n > PROTO_MAX_MOTORS) return 0;
      put32(body + n, m->u.state.seq); n += 4; put32(body + n, m->u.state.ack_seq); n += 4;
      put32(body + n, m->u.state.mcu_time_us); n += 4; put16(body + n, m->u.state.status); n += 2;
      put16(body + n, m->u.state.rx_errors); n += 2; body[n++] = m->u.state.n;
      body[n++] = m->u.state.flags & STATE_HAS_VELOCITIES;
      for (int i = 0; i < m->u.state.n; i++) { put32(body + n, (uint32_t)m->u.state.positions[i]); n += 4; }
      if (m->u.state.flags & STATE_HAS_VELOCITIES)
        for (int i = 0; i < m->u.state.n; i++) { put32(body + n, (uint32_t)m->u.state.velocities[i]); n += 4; }
      break;
    case MSG_CONFIG:
      put16(body + n, m->u.config.config_id); n += 2; put16(body + n, m->u.config.watchdog_ms); n += 2;
      body[n++] = m->u.config.telemetry; body[n++] = 0;
      put32(body + n, (uint32_t)m->u.config.max_speed); n += 4; break;
    case MSG_CONFIG_ACK:
      put16(body + n, m->u.config_ack.config_id); n += 2; body[n++] = m->u.config_ack.result; break;
    default: return 0;
  }
  put16(body + n, proto_crc16(body, n)); n += 2;
  size_t e = proto_cobs_encode(body, n, out);
  out[e++] = 0;
  return e;
}

int proto_decode_frame(const uint8_t *frame, size_t len, proto_msg_t *m) {
  uint8_t raw[PROTO_MAX_ENCODED];
  if (len > PROTO_MAX_ENCODED) return DEC_LENGTH;
  size_t n = proto_cobs_decode(frame, len, raw);
  if (n == (size_t)-1) return DEC_COBS;
  if (n < 3) return DEC_LENGTH;
  n -= 2;
  if (proto_crc16(raw, n) != get16(raw + n)) return DEC_CRC;
  const uint8_t *p = raw + 1;
  size_t pl = n - 1;
  memset(m, 0, sizeof *m);
  m->type = raw[0];
  switch (raw[0]) {
    case MSG_HELLO:
      if (pl != 4) return DEC_LENGTH;
      m->u.hello.version = p[0]; m->u.hello.n_motors = p[1]; m->u.hello.watchdog_ms = get16(p + 2);
      return DEC_OK;
    case MSG_ARM: case MSG_DISARM:
      return pl == 0 ? DEC_OK : DEC_LENGTH;
    case MSG_DEMAND: {
      if (pl < 9) return DEC_LENGTH;
      m->u.demand.seq = get32(p); m->u.demand.flags = p[4]; m->u.demand.mask = get32(p + 5);
      int k = popcount32(m->u.demand.mask);
      if (pl != 9 + 4 * (size_t)k) return DEC_LENGTH;
      m->u.demand.n = (uint8_t)k;
      for (int i = 0; i < k; i++) m->u.demand.counts[i] = (int32_t)get32(p + 9 + 4 * i);
      return DEC_OK;
    }
    case MSG_STATE: {
      if (pl < 18) return DEC_LENGTH;
      uint8_t k = p[16], flags = p[17];
      if (k > PROTO_MAX_MOTORS) return DEC_LENGTH;
      int has_vel = flags & STATE_HAS_VELOCITIES;
      if (pl != 18 + 4 * (size_t)k * (has_vel ? 2 : 1)) return DEC_LENGTH;
      m->u.state.seq = get32(p); m->u.state.ack_seq = get32(p + 4); m->u.state.mcu_time_us = get32(p + 8);
      m->u.state.status = get16(p + 12); m->u.state.rx_errors = get16(p + 14);
      m->u.state.n = k; m->u.state.flags = (uint8_t)has_vel;
      for (int i = 0; i < k; i++) m->u.state.positions[i] = (int32_t)get32(p + 18 + 4 * i);
      if (has_vel)
        for (int i = 0; i < k; i++) m->u.state.velocities[i] = (int32_t)get32(p + 18 + 4 * (k + i));
      return DEC_OK;
    }
    case MSG_CONFIG:
      if (pl != 10) return DEC_LENGTH;
      m->u.config.config_id = get16(p); m->u.config.watchdog_ms = get16(p + 2);
      m->u.config.telemetry = p[4]; m->u.config.max_speed = (int32_t)get32(p + 6);
      return DEC_OK;
    case MSG_CONFIG_ACK:
      if (pl != 3) return DEC_LENGTH;
      m->u.config_ack.config_id = get16(p); m->u.config_ack.result = p[2];
      return DEC_OK;
    default:
      return DEC_UNKNOWN_TYPE;
  }
}

void proto_decoder_init(proto_decoder_t *d) { memset(d, 0, sizeof *d); }

uint32_t proto_bad_frames(const proto_stats_t *s) {
  return s->crc_errors + s->cobs_errors + s->length_errors + s->unknown_type + s->overflow;
}

int proto_decoder_push(proto_decoder_t *d, uint8_t byte, proto_msg_t *msg) {
  if (byte != 0) {
    if (d->overflowing) return 0;
    if (d->len >= PROTO_MAX_ENCODED) { d->overflowing = 1; d->len = 0; d->stats.overflow++; return 0; }
    d->buf[d->len++] = byte;
    return 0;
  }
  size_t len = d->len;
  int overflowing = d->overflowing;
  d->len = 0; d->overflowing = 0;
  if (overflowing || len == 0) return 0;
  switch (proto_decode_frame(d->buf, len, msg)) {
    case DEC_OK: d->stats.frames++; return 1;
    case DEC_CRC: d->stats.crc_errors++; return 0;
    case DEC_COBS: d->stats.cobs_errors++; return 0;
    case DEC_UNKNOWN_TYPE: d->stats.unknown_type++; return 0;
    default: d->stats.length_errors++; return 0;
  }
}

int proto_seq_newer(uint32_t seq, uint32_t last) {
  uint32_t d = seq - last;
  return d != 0 && d < 0x80000000u;
}
