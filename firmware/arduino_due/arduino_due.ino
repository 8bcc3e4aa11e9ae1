// Arduino Due controller for the extensible rack-and-pinion arm (Hughes 2020): H-bridge PWM,
// quadrature encoders on interrupts, a position loop to the streamed demand, a 50 ms watchdog
// and a hardware e-stop input. The wire protocol core is plain C (protocol.c/.h, tested on the
// host by tests/test_hw_firmware.py); behaviour mirrors hw_bridge/device.py.
// CI compiles it for the Due's Cortex-M3 with arm-none-eabi-g++ -Werror against declarations
// of the Arduino API (target/check_cross_compile.sh); it is not linked with the Arduino core
// nor run on hardware here. Pin numbers below are placeholders: set them to your wiring.
#include "protocol.h"

#define N_MOTORS 6
static const uint8_t PIN_PWM[N_MOTORS] = {2, 3, 4, 5, 6, 7};       // H-bridge enable (PWM)
static const uint8_t PIN_DIR[N_MOTORS] = {22, 24, 26, 28, 30, 32}; // H-bridge direction
static const uint8_t PIN_ENC_A[N_MOTORS] = {23, 25, 27, 29, 31, 33};
static const uint8_t PIN_ENC_B[N_MOTORS] = {34, 36, 38, 40, 42, 44};
static const uint8_t PIN_ESTOP = 50;  // normally closed to GND; open (HIGH) = pressed

static const uint32_t PERIOD_US = 10000;   // 100 Hz control + telemetry timer
static uint16_t watchdog_ms = 50;
static const int32_t MAX_PWM = 255;
static int32_t max_speed_cps = 0;  // CONFIG: setpoint speed limit, counts/s (0: none)
static const int32_t KP_NUM = 2, KP_DEN = 1;  // PWM per count of error
static const int32_t DEADBAND = 2;            // counts

static volatile int32_t enc[N_MOTORS];
static int32_t target[N_MOTORS];
static int32_t setpoint[N_MOTORS];  // target approached at <= max_speed_cps
static int32_t last_pos[N_MOTORS];
static int32_t vel[N_MOTORS];
static bool armed = false, tripped = false, estop = false, send_velocities = false;
static bool seq_valid = false;
static uint32_t ack_seq = 0, state_seq = 0, last_demand_ms = 0, next_state_us = 0, next_tick_us = 0;
static proto_decoder_t decoder;

// Quadrature x4 decoding: on any edge of A or B, compare the channels.
template <int I> void encA() { enc[I] += (digitalRead(PIN_ENC_A[I]) == digitalRead(PIN_ENC_B[I])) ? 1 : -1; }
template <int I> void encB() { enc[I] += (digitalRead(PIN_ENC_A[I]) != digitalRead(PIN_ENC_B[I])) ? 1 : -1; }
typedef void (*isr_t)();
static const isr_t ISR_A[N_MOTORS] = {encA<0>, encA<1>, encA<2>, encA<3>, encA<4>, encA<5>};
static const isr_t ISR_B[N_MOTORS] = {encB<0>, encB<1>, encB<2>, encB<3>, encB<4>, encB<5>};

static int32_t position(int i) { noInterrupts(); int32_t p = enc[i]; interrupts(); return p; }

static void drive(int i, int32_t pwm) {
  digitalWrite(PIN_DIR[i], pwm >= 0 ? HIGH : LOW);
  analogWrite(PIN_PWM[i], (int)min(abs(pwm), MAX_PWM));
}

static void stop_all() {
  for (int i = 0; i < N_MOTORS; i++) { target[i] = setpoint[i] = position(i); drive(i, 0); }
}

static void send(const proto_msg_t *m) {
  uint8_t out[PROTO_MAX_ENCODED + 1];
  size_t n = proto_encode(m, out);
  if (n) SerialUSB.write(out, n);
}

static void send_state() {
  proto_msg_t m;
  memset(&m, 0, sizeof m);
  m.type = MSG_STATE;
  m.u.state.seq = ++state_seq;
  m.u.state.ack_seq = ack_seq;
  m.u.state.mcu_time_us = micros();
  m.u.state.status = (armed ? ST_ARMED : 0) | (tripped ? ST_WATCHDOG_TRIPPED : 0) | (estop ? ST_ESTOP : 0);
  uint32_t bad = proto_bad_frames(&decoder.stats);
  m.u.state.rx_errors = bad > 0xFFFF ? 0xFFFF : (uint16_t)bad;
  m.u.state.n = N_MOTORS;
  m.u.state.flags = send_velocities ? STATE_HAS_VELOCITIES : 0;
  for (int i = 0; i < N_MOTORS; i++) { m.u.state.positions[i] = position(i); m.u.state.velocities[i] = vel[i]; }
  send(&m);
  next_state_us = micros() + PERIOD_US;  // re-phase: one STATE per period
}

static void handle(const proto_msg_t *m) {
  proto_msg_t r;
  memset(&r, 0, sizeof r);
  switch (m->type) {
    case MSG_HELLO:
      seq_valid = false;
      r.type = MSG_HELLO; r.u.hello.version = PROTO_VERSION; r.u.hello.n_motors = N_MOTORS;
      r.u.hello.watchdog_ms = watchdog_ms; send(&r); break;
    case MSG_ARM:
      seq_valid = false;
      if (estop) break;
      armed = true; tripped = false; stop_all(); last_demand_ms = millis(); break;
    case MSG_DISARM:
      armed = false; stop_all(); break;
    case MSG_DEMAND: {
      if (seq_valid && !proto_seq_newer(m->u.demand.seq, ack_seq)) break;  // latest wins
      if (m->u.demand.mask >> N_MOTORS) break;
      seq_valid = true; ack_seq = m->u.demand.seq; last_demand_ms = millis();
      if (armed && !tripped) {
        int k = 0;
        for (int i = 0; i < N_MOTORS; i++) if (m->u.demand.mask >> i & 1u) target[i] = m->u.demand.counts[k++];
      }
      send_state();
      break;
    }
    case MSG_CONFIG: {
      bool ok = m->u.config.watchdog_ms >= 10 && m->u.config.watchdog_ms <= 1000 && m->u.config.max_speed >= 0;
      if (ok) {
        watchdog_ms = m->u.config.watchdog_ms;
        send_velocities = m->u.config.telemetry & TELEMETRY_VELOCITIES;
        if (m->u.config.max_speed) max_speed_cps = m->u.config.max_speed;
      }
      r.type = MSG_CONFIG_ACK; r.u.config_ack.config_id = m->u.config.config_id; r.u.config_ack.result = ok ? 0 : 1;
      send(&r);
      break;
    }
    default: break;
  }
}

void setup() {
  for (int i = 0; i < N_MOTORS; i++) {
    pinMode(PIN_PWM[i], OUTPUT); pinMode(PIN_DIR[i], OUTPUT); drive(i, 0);
    pinMode(PIN_ENC_A[i], INPUT_PULLUP); pinMode(PIN_ENC_B[i], INPUT_PULLUP);
    attachInterrupt(digitalPinToInterrupt(PIN_ENC_A[i]), ISR_A[i], CHANGE);
    attachInterrupt(digitalPinToInterrupt(PIN_ENC_B[i]), ISR_B[i], CHANGE);
  }
  pinMode(PIN_ESTOP, INPUT_PULLUP);
  proto_decoder_init(&decoder);
  SerialUSB.begin(0);  // native USB: the baud rate is ignored
  next_tick_us = next_state_us = micros() + PERIOD_US;
}

void loop() {
  proto_msg_t m;
  int budget = 512;  // bound the bytes handled per pass so the timer is never starved
  while (SerialUSB.available() && budget--) {
    if (proto_decoder_push(&decoder, (uint8_t)SerialUSB.read(), &m)) handle(&m);
  }
  estop = digitalRead(PIN_ESTOP) == HIGH;
  if (estop && armed) { armed = false; stop_all(); }

  uint32_t now = micros();
  if ((int32_t)(now - next_tick_us) >= 0) {
    next_tick_us += PERIOD_US;
    if ((int32_t)(now - next_tick_us) >= 0) next_tick_us = now + PERIOD_US;  // skip, no catch-up
    if (armed && millis() - last_demand_ms > watchdog_ms) { armed = false; tripped = true; stop_all(); }
    for (int i = 0; i < N_MOTORS; i++) {
      int32_t p = position(i);
      vel[i] = (p - last_pos[i]) * (int32_t)(1000000UL / PERIOD_US);
      last_pos[i] = p;
      int32_t step = max_speed_cps ? max_speed_cps / (int32_t)(1000000UL / PERIOD_US) : 0x7FFFFFFF;
      int32_t d = target[i] - setpoint[i];
      setpoint[i] += d > step ? step : (d < -step ? -step : d);
      int32_t err = setpoint[i] - p;
      drive(i, (armed && abs(err) > DEADBAND) ? err * KP_NUM / KP_DEN : 0);
    }
  }
  if ((int32_t)(micros() - next_state_us) >= 0) send_state();
}
