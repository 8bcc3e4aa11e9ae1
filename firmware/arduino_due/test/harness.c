/* Host test harness for protocol.c (not part of the sketch).
 *   harness decode : stdin lines of hex = byte chunks of a stream; stdout one text line per
 *                    decoded message, then "STATS frames crc cobs length unknown overflow".
 *   harness encode : stdin text lines (format below); stdout one hex frame (with 0x00) per line.
 * Text: HELLO v n wd | ARM | DISARM | DEMAND seq flags mask c.. | STATE seq ack t status rxerr
 *       n flags p.. [v..] | CONFIG id wd telemetry max_speed | CONFIG_ACK id result  (decimal) */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../protocol.h"

static void print_msg(const proto_msg_t *m) {
  switch (m->type) {
    case MSG_HELLO: printf("HELLO %u %u %u", m->u.hello.version, m->u.hello.n_motors, m->u.hello.watchdog_ms); break;
    case MSG_ARM: printf("ARM"); break;
    case MSG_DISARM: printf("DISARM"); break;
    case MSG_DEMAND:
      printf("DEMAND %lu %u %lu", (unsigned long)m->u.demand.seq, m->u.demand.flags, (unsigned long)m->u.demand.mask);
      for (int i = 0; i < m->u.demand.n; i++) printf(" %ld", (long)m->u.demand.counts[i]);
      break;
    case MSG_STATE:
      printf("STATE %lu %lu %lu %u %u %u %u", (unsigned long)m->u.state.seq, (unsigned long)m->u.state.ack_seq,
             (unsigned long)m->u.state.mcu_time_us, m->u.state.status, m->u.state.rx_errors, m->u.state.n,
             m->u.state.flags);
      for (int i = 0; i < m->u.state.n; i++) printf(" %ld", (long)m->u.state.positions[i]);
      if (m->u.state.flags & STATE_HAS_VELOCITIES)
        for (int i = 0; i < m->u.state.n; i++) printf(" %ld", (long)m->u.state.velocities[i]);
      break;
    case MSG_CONFIG:
      printf("CONFIG %u %u %u %ld", m->u.config.config_id, m->u.config.watchdog_ms, m->u.config.telemetry,
             (long)m->u.config.max_speed);
      break;
    case MSG_CONFIG_ACK: printf("CONFIG_ACK %u %u", m->u.config_ack.config_id, m->u.config_ack.result); break;
  }
  printf("\n");
}

static int decode_mode(void) {
  static char line[1 << 16];
  proto_decoder_t d;
  proto_msg_t m;
  proto_decoder_init(&d);
  while (fgets(line, sizeof line, stdin)) {
    for (char *p = line; p[0] && p[1] && p[0] != '\n'; p += 2) {
      unsigned v;
      if (sscanf(p, "%2x", &v) != 1) return 2;
      if (proto_decoder_push(&d, (uint8_t)v, &m)) print_msg(&m);
    }
  }
  printf("STATS %lu %lu %lu %lu %lu %lu\n", (unsigned long)d.stats.frames, (unsigned long)d.stats.crc_errors,
         (unsigned long)d.stats.cobs_errors, (unsigned long)d.stats.length_errors,
         (unsigned long)d.stats.unknown_type, (unsigned long)d.stats.overflow);
  return 0;
}

static int encode_mode(void) {
  static char line[1 << 16];
  while (fgets(line, sizeof line, stdin)) {
    proto_msg_t m;
    memset(&m, 0, sizeof m);
    char *save = NULL, *tok = strtok_r(line, " \n", &save);
    if (!tok) continue;
    long long v[2 * PROTO_MAX_MOTORS + 16];
    int n = 0;
    for (char *t; (t = strtok_r(NULL, " \n", &save)) && n < (int)(sizeof v / sizeof v[0]);) v[n++] = strtoll(t, NULL, 10);
    if (!strcmp(tok, "HELLO")) { m.type = MSG_HELLO; m.u.hello.version = (uint8_t)v[0]; m.u.hello.n_motors = (uint8_t)v[1]; m.u.hello.watchdog_ms = (uint16_t)v[2]; }
    else if (!strcmp(tok, "ARM")) m.type = MSG_ARM;
    else if (!strcmp(tok, "DISARM")) m.type = MSG_DISARM;
    else if (!strcmp(tok, "DEMAND")) {
      m.type = MSG_DEMAND; m.u.demand.seq = (uint32_t)v[0]; m.u.demand.flags = (uint8_t)v[1]; m.u.demand.mask = (uint32_t)v[2];
      m.u.demand.n = (uint8_t)(n - 3);
      for (int i = 0; i < n - 3; i++) m.u.demand.counts[i] = (int32_t)v[3 + i];
    } else if (!strcmp(tok, "STATE")) {
      m.type = MSG_STATE; m.u.state.seq = (uint32_t)v[0]; m.u.state.ack_seq = (uint32_t)v[1];
      m.u.state.mcu_time_us = (uint32_t)v[2]; m.u.state.status = (uint16_t)v[3]; m.u.state.rx_errors = (uint16_t)v[4];
      m.u.state.n = (uint8_t)v[5]; m.u.state.flags = (uint8_t)v[6];
      for (int i = 0; i < m.u.state.n; i++) m.u.state.positions[i] = (int32_t)v[7 + i];
      if (m.u.state.flags & STATE_HAS_VELOCITIES)
        for (int i = 0; i < m.u.state.n; i++) m.u.state.velocities[i] = (int32_t)v[7 + m.u.state.n + i];
    } else if (!strcmp(tok, "CONFIG")) {
      m.type = MSG_CONFIG; m.u.config.config_id = (uint16_t)v[0]; m.u.config.watchdog_ms = (uint16_t)v[1];
      m.u.config.telemetry = (uint8_t)v[2]; m.u.config.max_speed = (int32_t)v[3];
    } else if (!strcmp(tok, "CONFIG_ACK")) { m.type = MSG_CONFIG_ACK; m.u.config_ack.config_id = (uint16_t)v[0]; m.u.config_ack.result = (uint8_t)v[1]; }
    else { printf("ERROR unknown %s\n", tok); continue; }
    uint8_t out[PROTO_MAX_ENCODED + 1];
    size_t len = proto_encode(&m, out);
    if (!len) { printf("ERROR invalid\n"); continue; }
    for (size_t i = 0; i < len; i++) printf("%02x", out[i]);
    printf("\n");
  }
  return 0;
}

int main(int argc, char **argv) {
  if (argc == 2 && !strcmp(argv[1], "decode")) return decode_mode();
  if (argc == 2 && !strcmp(argv[1], "encode")) return encode_mode();
  fprintf(stderr, "usage: %s decode|encode\n", argv[0]);
  return 2;
}
