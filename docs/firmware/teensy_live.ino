// Device side of the active-contacts live protocol (docs/live.md) for a Teensy-class board.
//
// UNTESTED ON HARDWARE: written against the Arduino API (Teensyduino: IntervalTimer,
// attachInterrupt, analogWrite, Serial over USB), compiled only against stand-ins of those
// functions; no board has run it. Set the pins,
// the counts per revolution, the rate and the speed-to-PWM law for your rig.
//
// What it does: counts every encoder in quadrature (interrupts), samples them all at RATE_HZ
// on a timer, sends "S,seq,us,central,w_1..w_n" with its CRC-16/CCITT-FALSE, applies each
// "C,seq,u_1..u_n" that answers the current sample, answers "HELLO?" with its handshake, starts
// on "START", and sets every wheel to zero on "STOP" or when no command came for 3 periods
// (the watchdog).

#include <Arduino.h>
#include <stdlib.h>
#include <string.h>

// ---- the rig (edit) ------------------------------------------------------------------------
static const int N_WHEELS = 10;
static const float RATE_HZ = 50.0f;
static const float CENTRAL_CPR = 8192.0f;          // AMT103-V
static const float WHEEL_CPR = 3591.84f;           // 48 CPR x 74.83:1 at the wheel
static const float SPEED_LIMIT = 0.35f;            // m/s at the contact
static const uint8_t CENTRAL_A = 0, CENTRAL_B = 1;
static const uint8_t WHEEL_A[N_WHEELS] = {2, 4, 6, 8, 10, 12, 14, 16, 18, 20};
static const uint8_t WHEEL_B[N_WHEELS] = {3, 5, 7, 9, 11, 13, 15, 17, 19, 21};
static const uint8_t MOTOR_PWM[N_WHEELS] = {22, 23, 24, 25, 28, 29, 33, 36, 37, 14};
static const uint8_t MOTOR_DIR[N_WHEELS] = {26, 27, 30, 31, 32, 34, 35, 38, 39, 40};
static const int WATCHDOG_PERIODS = 3;

// ---- encoders: quadrature counts, updated in interrupts -------------------------------------
static volatile int32_t central_count = 0;
static volatile int32_t wheel_count[N_WHEELS];
static volatile uint8_t central_state = 0;
static volatile uint8_t wheel_state[N_WHEELS];
// Gray-code transition table: +1, -1 or 0 for (previous << 2 | current).
static const int8_t QUAD[16] = {0, 1, -1, 0, -1, 0, 0, 1, 1, 0, 0, -1, 0, -1, 1, 0};

static void central_isr() {
  uint8_t now = (digitalReadFast(CENTRAL_A) << 1) | digitalReadFast(CENTRAL_B);
  central_count += QUAD[(central_state << 2) | now];
  central_state = now;
}

template <int I> static void wheel_isr() {
  uint8_t now = (digitalReadFast(WHEEL_A[I]) << 1) | digitalReadFast(WHEEL_B[I]);
  wheel_count[I] += QUAD[(wheel_state[I] << 2) | now];
  wheel_state[I] = now;
}

typedef void (*Isr)();
static const Isr WHEEL_ISR[N_WHEELS] = {wheel_isr<0>, wheel_isr<1>, wheel_isr<2>, wheel_isr<3>, wheel_isr<4>,
                                        wheel_isr<5>, wheel_isr<6>, wheel_isr<7>, wheel_isr<8>, wheel_isr<9>};

// ---- the line protocol ------------------------------------------------------------------------
static uint16_t crc16(const char *data, size_t length) {       // CRC-16/CCITT-FALSE
  uint16_t crc = 0xFFFF;
  for (size_t i = 0; i < length; ++i) {
    crc ^= (uint16_t)(uint8_t)data[i] << 8;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
  }
  return crc;
}

static void send_line(const char *body) {                      // "$body*CCCC\n"
  char tail[8];
  snprintf(tail, sizeof tail, "*%04X\n", crc16(body, strlen(body)));
  Serial.write('$');
  Serial.write(body, strlen(body));
  Serial.write(tail, strlen(tail));
}

// ---- the motors -----------------------------------------------------------------------------
static float command[N_WHEELS];                                // m/s at the contact

static void drive(int i, float speed) {
  // Placeholder law: PWM proportional to the commanded speed. A rig closes a speed loop on
  // its wheel encoder here (the toolkit's motor model: first-order lag, docs/physics.md).
  speed = constrain(speed, -SPEED_LIMIT, SPEED_LIMIT);
  digitalWriteFast(MOTOR_DIR[i], speed < 0 ? HIGH : LOW);
  analogWrite(MOTOR_PWM[i], (int)(fabsf(speed) / SPEED_LIMIT * 4095.0f + 0.5f));
}

static void stop_wheels() {
  for (int i = 0; i < N_WHEELS; ++i) { command[i] = 0.0f; drive(i, 0.0f); }
}

// ---- sampling -------------------------------------------------------------------------------
static IntervalTimer sampler;
static volatile bool sample_due = false;
static bool running = false;
static uint32_t next_seq = 0;               // the sequence number of the next sample
static uint32_t current = 0;                // the sequence number of the last sample sent
static uint32_t started_us = 0;
static uint32_t last_command_seq = 0;
static int32_t snap_central, snap_wheel[N_WHEELS];
static uint32_t snap_us;

static void sample_isr() {                  // every counter read at one instant
  snap_us = micros() - started_us;
  snap_central = central_count;
  for (int i = 0; i < N_WHEELS; ++i) snap_wheel[i] = wheel_count[i];
  sample_due = true;
}

static void send_sample() {
  char body[24 + 12 * (N_WHEELS + 1)];
  int at = snprintf(body, sizeof body, "S,%lu,%lu,%ld", (unsigned long)current, (unsigned long)snap_us,
                    (long)snap_central);
  for (int i = 0; i < N_WHEELS; ++i) at += snprintf(body + at, sizeof body - at, ",%ld", (long)snap_wheel[i]);
  send_line(body);
}

// ---- commands from the host -----------------------------------------------------------------
static char line[512];
static size_t line_length = 0;

static bool checked_body(char *text, size_t length, char **body) {   // "$body*CCCC" -> body
  if (length < 6 || text[0] != '$' || text[length - 5] != '*') return false;
  text[length - 5] = '\0';
  char *end;
  unsigned long stated = strtoul(text + length - 4, &end, 16);
  if (*end != '\0' || stated != crc16(text + 1, length - 6)) return false;
  *body = text + 1;
  return true;
}

static void handle(char *body) {
  if (strcmp(body, "HELLO?,1") == 0) {
    char hello[96];
    snprintf(hello, sizeof hello, "HELLO,1,%d,%.6g,%.6g,%.6g", N_WHEELS, (double)RATE_HZ, (double)CENTRAL_CPR,
             (double)WHEEL_CPR);
    send_line(hello);
  } else if (strcmp(body, "START") == 0) {
    noInterrupts();
    next_seq = 0;
    current = 0;
    last_command_seq = 0;
    started_us = micros();
    interrupts();
    running = true;
    sampler.begin(sample_isr, 1e6f / RATE_HZ);
    sample_isr();                           // sample 0 at device time 0
  } else if (strcmp(body, "STOP") == 0) {
    sampler.end();
    running = false;
    stop_wheels();
  } else if (body[0] == 'C' && body[1] == ',') {
    char *cursor = body + 2, *end;
    unsigned long answered = strtoul(cursor, &end, 10);
    if (end == cursor || *end != ',' || answered != current || !running) return;   // late or malformed
    float speeds[N_WHEELS];
    for (int i = 0; i < N_WHEELS; ++i) {
      cursor = end + 1;
      speeds[i] = strtof(cursor, &end);
      if (end == cursor || (i + 1 < N_WHEELS ? *end != ',' : *end != '\0')) return;
    }
    for (int i = 0; i < N_WHEELS; ++i) { command[i] = speeds[i]; drive(i, speeds[i]); }
    last_command_seq = current;
  }
}

static void read_host() {
  while (Serial.available() > 0) {
    char c = (char)Serial.read();
    if (c == '\n') {
      if (line_length > 0 && line[line_length - 1] == '\r') --line_length;
      line[line_length] = '\0';
      char *body;
      if (checked_body(line, line_length, &body)) handle(body);   // a bad line is skipped
      line_length = 0;
    } else if (line_length + 1 < sizeof line) {
      line[line_length++] = c;
    } else {
      line_length = 0;                      // too long: drop it
    }
  }
}

// ---- Arduino ----------------------------------------------------------------------------------
void setup() {
  Serial.begin(115200);                     // USB serial: full USB speed whatever the baud
  pinMode(CENTRAL_A, INPUT_PULLUP);
  pinMode(CENTRAL_B, INPUT_PULLUP);
  attachInterrupt(digitalPinToInterrupt(CENTRAL_A), central_isr, CHANGE);
  attachInterrupt(digitalPinToInterrupt(CENTRAL_B), central_isr, CHANGE);
  analogWriteResolution(12);
  for (int i = 0; i < N_WHEELS; ++i) {
    pinMode(WHEEL_A[i], INPUT_PULLUP);
    pinMode(WHEEL_B[i], INPUT_PULLUP);
    attachInterrupt(digitalPinToInterrupt(WHEEL_A[i]), WHEEL_ISR[i], CHANGE);
    attachInterrupt(digitalPinToInterrupt(WHEEL_B[i]), WHEEL_ISR[i], CHANGE);
    pinMode(MOTOR_PWM[i], OUTPUT);
    pinMode(MOTOR_DIR[i], OUTPUT);
  }
  stop_wheels();
}

void loop() {
  read_host();
  if (running && !Serial.dtr()) {           // the host closed the port
    sampler.end();
    running = false;
    stop_wheels();
  }
  if (sample_due) {
    sample_due = false;
    if (running) {
      current = next_seq++;
      if (current - last_command_seq > (uint32_t)WATCHDOG_PERIODS) stop_wheels();   // the watchdog: 3 periods unanswered
      send_sample();
    }
  }
}
