// fpp-rig trigger box firmware: trigger protocol version 2 (docs/trigger-protocol.md).
//
// Board: Arduino Uno (ATmega328P, 16 MHz). CI builds it with avr-gcc against Debian's Arduino
// core (tests/test_trigger_box_firmware.py) and, for the PC, against the stand-in in host/;
// with the Arduino tools: arduino-cli compile --fqbn arduino:avr:uno firmware/trigger_box
//
// The host sends checksummed ASCII lines "<id> <COMMAND> [args]*HH\n"; the box answers
// "<id> OK [data]*HH\n" or "<id> ERR <code> <NAME> [text]*HH\n" and sends events "! <EVENT> ...".
// A request identical to the last executed one (same id, command and arguments) is answered
// from the reply cache and not executed again (a retried FIRE never fires twice).
// mock_devices/trigger_box.py emulates this firmware; keep the two in step.
//
// Pins: D8 pulse out (camera trigger), D2 sync in (INT0, rising edge; fit an external pull-down),
// D13 LED (armed).
//
// Timing does not depend on the main loop or serial traffic: a sync edge is taken in the INT0
// interrupt, which starts Timer1; the delay and the pulse are timed by Timer1 compare-match
// interrupts that switch the output (0.5 us ticks). Edges closer than LOCKOUT_US to the previous
// one are ringing and ignored; an edge while a pulse is pending or active is counted as missed
// and reported ("! MISSED <total>", STATUS miss=). The output's idle level is the polarity kept
// in EEPROM, written before the pin becomes an output, so a NEG box never idles active.

#include <Arduino.h>
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/pgmspace.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const uint8_t PROTOCOL_VERSION = 2;
static const char FIRMWARE_ID[] PROGMEM = "fpp-trigger-box/2.0.0";

static const uint8_t PIN_PULSE = 8;
static const uint8_t PIN_SYNC = 2;
static const uint8_t PIN_LED = 13;

static const uint8_t MAX_LINE = 96;  // bytes including "*HH\n"
static const uint8_t MAX_TOKENS = 8;
static const unsigned long WATCHDOG_MS = 10000UL;
static const unsigned long MAX_WIDTH_US = 1000000UL;
static const unsigned long MAX_DELAY_US = 1000000UL;
static const unsigned long MAX_ARM = 65535UL;
static const unsigned long DEFAULT_WIDTH_US = 100UL;
static const unsigned long LOCKOUT_US = 20UL;  // edges closer than this are ringing
static const uint8_t EEPROM_POLARITY = 0;      // 0x4E ('N'): NEG; anything else: POS

enum ErrorCode {
  ERR_UNKNOWN_COMMAND = 1,
  ERR_BAD_ARGUMENT = 2,
  ERR_NOT_ARMED = 3,
  ERR_STATE = 4,
  ERR_VERSION = 5,
  ERR_BAD_CHECKSUM = 6,
  ERR_SYNTAX = 7,
  ERR_NO_HELLO = 8,
};

// Texts live in flash (PSTR / F): the ATmega328P has 2 KiB of RAM.
static PGM_P errorName(uint8_t code) {
  switch (code) {
    case ERR_UNKNOWN_COMMAND: return PSTR("UNKNOWN_COMMAND");
    case ERR_BAD_ARGUMENT: return PSTR("BAD_ARGUMENT");
    case ERR_NOT_ARMED: return PSTR("NOT_ARMED");
    case ERR_STATE: return PSTR("STATE");
    case ERR_VERSION: return PSTR("VERSION");
    case ERR_BAD_CHECKSUM: return PSTR("BAD_CHECKSUM");
    case ERR_SYNTAX: return PSTR("SYNTAX");
    default: return PSTR("NO_HELLO");
  }
}

enum BoxState { STATE_IDLE, STATE_ARMED, STATE_DONE };

// -- settings and state ----------------------------------------------------------------------
// Written by the command loop, read by the interrupts: volatile, so every access goes to memory in
// program order (the loop sets a value before the state that lets an interrupt use it).
static volatile unsigned long widthUs = DEFAULT_WIDTH_US;
static volatile unsigned long delayUs = 0;
static volatile bool activeHigh = true;
static volatile BoxState state = STATE_IDLE;
static volatile bool sourceExt = false;
static volatile unsigned long armedCount = 0;
static bool helloDone = false;

static char lastRequest[MAX_LINE + 1] = "";  // the last executed request line, as received
static char lastReply[MAX_LINE + 1] = "";    // its reply body, without "*HH"
static unsigned long lastLineMs = 0;

static char lineBuf[MAX_LINE + 2];
static uint8_t lineLen = 0;
static bool lineOverflow = false;

// -- pulse timing: Timer1 and INT0 -------------------------------------------------------------
// Timer1 runs in CTC mode at F_CPU / 8 (2 ticks per us); a phase longer than one 16-bit period
// is counted down in chunks.
static const uint32_t TICKS_PER_US = 2;
enum PulsePhase { PHASE_IDLE, PHASE_DELAY, PHASE_ACTIVE };
static volatile uint8_t phase = PHASE_IDLE;
static volatile uint32_t ticksLeft = 0;
static volatile unsigned long pulsesStarted = 0;  // since ARM
static volatile unsigned long pulsesDone = 0;     // since ARM
static volatile unsigned long edgesMissed = 0;    // since ARM
static volatile unsigned long lastEdgeUs = 0;
static volatile bool edgeSeen = false;
static unsigned long pulsesReported = 0;
static unsigned long missedReported = 0;

static inline void outputActive(bool active) {
  // D8 is PB0; writing the port register keeps the edge inside the interrupt
  if (active == activeHigh) {
    PORTB |= _BV(PB0);
  } else {
    PORTB &= (uint8_t)~_BV(PB0);
  }
}

static void timerLoad() {
  uint32_t chunk = ticksLeft > 65536UL ? 65536UL : ticksLeft;
  OCR1A = (uint16_t)(chunk - 1);
}

static void timerStart(uint32_t ticks) {
  ticksLeft = ticks;
  TCCR1A = 0;
  TCNT1 = 0;
  timerLoad();
  TIFR1 = _BV(OCF1A);
  TIMSK1 |= _BV(OCIE1A);
  TCCR1B = _BV(WGM12) | _BV(CS11);  // CTC, F_CPU / 8
}

static void timerStop() {
  TCCR1B = 0;
  TIMSK1 &= (uint8_t)~_BV(OCIE1A);
}

// Begin one exposure: the delay, then the active level for widthUs. Interrupts off.
static void startPulseLocked() {
  pulsesStarted++;
  if (delayUs == 0) {
    outputActive(true);
    phase = PHASE_ACTIVE;
    timerStart(widthUs * TICKS_PER_US);
  } else {
    phase = PHASE_DELAY;
    timerStart(delayUs * TICKS_PER_US);
  }
}

ISR(TIMER1_COMPA_vect) {
  uint32_t chunk = (uint32_t)OCR1A + 1;
  ticksLeft = ticksLeft > chunk ? ticksLeft - chunk : 0;
  if (ticksLeft) {
    timerLoad();
    return;
  }
  if (phase == PHASE_DELAY) {
    outputActive(true);
    phase = PHASE_ACTIVE;
    ticksLeft = widthUs * TICKS_PER_US;
    timerLoad();
  } else {
    outputActive(false);
    timerStop();
    phase = PHASE_IDLE;
    pulsesDone++;
  }
}

// A rising edge on the sync input (D2).
ISR(INT0_vect) {
  unsigned long now = micros();
  if (edgeSeen && now - lastEdgeUs < LOCKOUT_US) return;  // ringing
  edgeSeen = true;
  lastEdgeUs = now;
  if (state != STATE_ARMED || !sourceExt || pulsesStarted >= armedCount) return;
  if (phase != PHASE_IDLE) {
    edgesMissed++;
    return;
  }
  startPulseLocked();
}

static bool pulseBusy() {
  noInterrupts();
  bool busy = phase != PHASE_IDLE;
  interrupts();
  return busy;
}

// -- output ----------------------------------------------------------------------------------
static uint8_t xorOf(const char *body) {
  uint8_t value = 0;
  for (const char *p = body; *p; ++p) value ^= (uint8_t)*p;
  return value;
}

static char hexDigit(uint8_t v) { return (char)(v < 10 ? '0' + v : 'A' + v - 10); }

static void sendLine(const char *body) {
  uint8_t cs = xorOf(body);
  Serial.print(body);
  Serial.write('*');
  Serial.write(hexDigit(cs >> 4));
  Serial.write(hexDigit(cs & 0x0F));
  Serial.write('\n');
}

// name: a flash string
static void sendEvent(PGM_P name, long value, bool withValue) {
  char body[32];
  if (withValue) {
    snprintf_P(body, sizeof body, PSTR("! %S %ld"), name, value);
  } else {
    snprintf_P(body, sizeof body, PSTR("! %S"), name);
  }
  sendLine(body);
}

// Build the reply into lastReply (the cache) and send it; data is in RAM.
static void replyOk(unsigned long id, const char *data) {
  if (data && *data) {
    snprintf_P(lastReply, sizeof lastReply, PSTR("%lu OK %s"), id, data);
  } else {
    snprintf_P(lastReply, sizeof lastReply, PSTR("%lu OK"), id);
  }
  sendLine(lastReply);
}

// text: a flash string, or (textInRam) a RAM string
static void replyError(unsigned long id, uint8_t code, PGM_P text, bool textInRam = false) {
  snprintf_P(lastReply, sizeof lastReply, textInRam ? PSTR("%lu ERR %u %S %s") : PSTR("%lu ERR %u %S %S"),
             id, code, errorName(code), text);
  sendLine(lastReply);
}

// Errors about unreadable requests use id 0 and are not cached.
static void rejectLine(uint8_t code) {
  char body[48];
  snprintf_P(body, sizeof body, PSTR("0 ERR %u %S request rejected"), code, errorName(code));
  sendLine(body);
}

// -- pulses ----------------------------------------------------------------------------------
static void setIdle() {
  noInterrupts();
  timerStop();
  phase = PHASE_IDLE;
  outputActive(false);
  interrupts();
}

// Report pulses finished since the last call ("! PULSE <index>", then "! DONE <n>" after the
// last), and missed edges once no pulse is in flight ("! MISSED <total>").
static void servicePulses(bool holdDone) {
  noInterrupts();
  unsigned long done = pulsesDone;
  unsigned long missed = edgesMissed;
  bool busy = phase != PHASE_IDLE;
  interrupts();
  while (pulsesReported < done) {
    sendEvent(PSTR("PULSE"), (long)pulsesReported, true);
    pulsesReported++;
    if (pulsesReported >= armedCount && state == STATE_ARMED) {
      state = STATE_DONE;
      digitalWrite(PIN_LED, LOW);
      if (!holdDone) sendEvent(PSTR("DONE"), (long)armedCount, true);
    }
  }
  if (!busy && missed != missedReported) {
    missedReported = missed;
    sendEvent(PSTR("MISSED"), (long)missed, true);
  }
}

static void clearCounters() {
  noInterrupts();
  pulsesStarted = 0;
  pulsesDone = 0;
  edgesMissed = 0;
  interrupts();
  pulsesReported = 0;
  missedReported = 0;
}

static void disarm() {
  state = STATE_IDLE;
  armedCount = 0;
  setIdle();
  clearCounters();
  digitalWrite(PIN_LED, LOW);
}

static void restoreDefaults() {
  disarm();
  widthUs = DEFAULT_WIDTH_US;
  delayUs = 0;
  sourceExt = false;
}

// -- parsing ---------------------------------------------------------------------------------
static bool isTokenChar(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
         c == '_' || c == '.' || c == '=' || c == ':' || c == '/' || c == '+' || c == '-';
}

// Decimal integer of at most 7 digits in [lo, hi]; false if not.
static bool parseUnsigned(const char *token, unsigned long lo, unsigned long hi,
                          unsigned long *out) {
  size_t n = strlen(token);
  if (n == 0 || n > 7) return false;
  for (size_t i = 0; i < n; ++i) {
    if (token[i] < '0' || token[i] > '9') return false;
  }
  unsigned long value = strtoul(token, NULL, 10);
  if (value < lo || value > hi) return false;
  *out = value;
  return true;
}

static int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// -- commands --------------------------------------------------------------------------------
static void execute(unsigned long id, char *command, char **args, uint8_t nargs) {
  char data[MAX_LINE];
  unsigned long a = 0, b = 0;

  bool known = !strcmp_P(command, PSTR("HELLO")) || !strcmp_P(command, PSTR("PING")) ||
               !strcmp_P(command, PSTR("CONFIG")) || !strcmp_P(command, PSTR("ARM")) ||
               !strcmp_P(command, PSTR("FIRE")) || !strcmp_P(command, PSTR("STATUS")) ||
               !strcmp_P(command, PSTR("RESET"));
  if (!known) {
    replyError(id, ERR_UNKNOWN_COMMAND, command, true);
    return;
  }
  if (!helloDone && strcmp_P(command, PSTR("HELLO")) && strcmp_P(command, PSTR("PING"))) {
    replyError(id, ERR_NO_HELLO, PSTR("send HELLO first"));
    return;
  }

  if (!strcmp_P(command, PSTR("HELLO"))) {
    if (nargs != 1 || !parseUnsigned(args[0], 0, 255, &a)) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("HELLO takes one version"));
    } else if (a != PROTOCOL_VERSION) {
      snprintf_P(data, sizeof data, PSTR("box speaks %u"), PROTOCOL_VERSION);
      replyError(id, ERR_VERSION, data, true);
    } else {
      helloDone = true;
      snprintf_P(data, sizeof data, PSTR("%u %S"), PROTOCOL_VERSION, FIRMWARE_ID);
      replyOk(id, data);
    }
  } else if (!strcmp_P(command, PSTR("PING"))) {
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("PING takes no argument"));
    } else {
      replyOk(id, "");
    }
  } else if (!strcmp_P(command, PSTR("CONFIG"))) {
    bool positive = nargs == 3 && !strcmp_P(args[2], PSTR("POS"));
    bool negative = nargs == 3 && !strcmp_P(args[2], PSTR("NEG"));
    if (nargs != 3 || !parseUnsigned(args[0], 1, MAX_WIDTH_US, &a) ||
        !parseUnsigned(args[1], 0, MAX_DELAY_US, &b) || !(positive || negative)) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("CONFIG takes width_us delay_us POS or NEG"));
    } else if (state == STATE_ARMED) {
      replyError(id, ERR_STATE, PSTR("armed RESET first"));
    } else {
      widthUs = a;
      delayUs = b;
      if (activeHigh != positive) {
        activeHigh = positive;
        eeprom_update_byte((uint8_t *)EEPROM_POLARITY, activeHigh ? 'P' : 'N');  // idle level at boot
      }
      setIdle();
      snprintf_P(data, sizeof data, PSTR("%lu %lu %S"), widthUs, delayUs, activeHigh ? PSTR("POS") : PSTR("NEG"));
      replyOk(id, data);
    }
  } else if (!strcmp_P(command, PSTR("ARM"))) {
    bool ext = nargs == 2 && !strcmp_P(args[1], PSTR("EXT"));
    bool sw = nargs == 1 || (nargs == 2 && !strcmp_P(args[1], PSTR("SW")));
    if (nargs < 1 || nargs > 2 || !parseUnsigned(args[0], 1, MAX_ARM, &a) || !(ext || sw)) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("ARM takes count SW or EXT"));
    } else if (state == STATE_ARMED) {
      replyError(id, ERR_STATE, PSTR("already armed RESET first"));
    } else {
      clearCounters();
      noInterrupts();
      sourceExt = ext;
      armedCount = a;
      state = STATE_ARMED;
      interrupts();
      digitalWrite(PIN_LED, HIGH);
      snprintf_P(data, sizeof data, PSTR("%lu %S"), armedCount, sourceExt ? PSTR("EXT") : PSTR("SW"));
      replyOk(id, data);
    }
  } else if (!strcmp_P(command, PSTR("FIRE"))) {
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("FIRE takes no argument"));
    } else if (state != STATE_ARMED) {
      replyError(id, ERR_NOT_ARMED, PSTR("ARM first"));
    } else if (sourceExt) {
      replyError(id, ERR_STATE, PSTR("armed for EXT sync"));
    } else {
      noInterrupts();
      unsigned long index = pulsesStarted;
      startPulseLocked();
      interrupts();
      while (pulseBusy()) delayMicroseconds(1);  // the timer interrupts time the pulse
      servicePulses(true);
      snprintf_P(data, sizeof data, PSTR("%lu"), index);
      replyOk(id, data);
      if (state == STATE_DONE) sendEvent(PSTR("DONE"), (long)armedCount, true);
    }
  } else if (!strcmp_P(command, PSTR("STATUS"))) {
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("STATUS takes no argument"));
    } else {
      PGM_P name = state == STATE_ARMED ? PSTR("ARMED") : (state == STATE_DONE ? PSTR("DONE") : PSTR("IDLE"));
      noInterrupts();
      unsigned long fired = pulsesDone;
      unsigned long missed = edgesMissed;
      interrupts();
      // at most 88 bytes with "*HH\n" (protocol limit 96)
      snprintf_P(data, sizeof data, PSTR("st=%S n=%lu fired=%lu miss=%lu w=%lu d=%lu pol=%S src=%S"), name,
                 armedCount, fired, missed, widthUs, delayUs, activeHigh ? PSTR("POS") : PSTR("NEG"),
                 sourceExt ? PSTR("EXT") : PSTR("SW"));
      replyOk(id, data);
    }
  } else {  // RESET
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, PSTR("RESET takes no argument"));
    } else {
      restoreDefaults();
      replyOk(id, "");
    }
  }
}

// One complete line without its '\n' (a trailing '\r' is dropped here).
static void handleLine(char *line, uint8_t len) {
  lastLineMs = millis();
  if (len && line[len - 1] == '\r') line[--len] = '\0';
  char received[MAX_LINE + 1];
  strncpy(received, line, sizeof received - 1);
  received[sizeof received - 1] = '\0';

  // checksum: "...*HH"
  if (len < 3 || line[len - 3] != '*' || hexValue(line[len - 2]) < 0 ||
      hexValue(line[len - 1]) < 0) {
    rejectLine(ERR_BAD_CHECKSUM);
    return;
  }
  uint8_t expected = (uint8_t)(hexValue(line[len - 2]) * 16 + hexValue(line[len - 1]));
  line[len - 3] = '\0';
  if (xorOf(line) != expected) {
    rejectLine(ERR_BAD_CHECKSUM);
    return;
  }

  // tokens separated by single spaces, each of [A-Za-z0-9_.=:/+-]
  char *tokens[MAX_TOKENS];
  uint8_t ntokens = 0;
  char *p = line;
  while (true) {
    char *start = p;
    while (*p && *p != ' ') {
      if (!isTokenChar(*p)) {
        rejectLine(ERR_SYNTAX);
        return;
      }
      ++p;
    }
    if (p == start || ntokens == MAX_TOKENS) {  // empty token or too many
      rejectLine(ERR_SYNTAX);
      return;
    }
    tokens[ntokens++] = start;
    if (!*p) break;
    *p++ = '\0';
  }
  unsigned long id = 0;
  if (ntokens < 2 || !parseUnsigned(tokens[0], 1, 65535UL, &id) || strlen(tokens[0]) > 5) {
    rejectLine(ERR_SYNTAX);
    return;
  }
  for (char *c = tokens[1]; *c; ++c) {
    if (*c >= 'a' && *c <= 'z') *c -= 'a' - 'A';
  }

  if (lastReply[0] && !strcmp(received, lastRequest)) {  // a retransmission: answer again
    sendLine(lastReply);
    return;
  }
  strcpy(lastRequest, received);
  execute(id, tokens[1], tokens + 2, ntokens - 2);
}

// -- main loop -------------------------------------------------------------------------------
void setup() {
  // first: the pulse output's idle level (from EEPROM), set before the pin drives, so a camera
  // armed on the opposite edge sees no spurious trigger; until here the pin floated (input)
  activeHigh = eeprom_read_byte((const uint8_t *)EEPROM_POLARITY) != 'N';
  outputActive(false);
  pinMode(PIN_PULSE, OUTPUT);
  pinMode(PIN_LED, OUTPUT);
  pinMode(PIN_SYNC, INPUT);  // no internal pull-up: the board's pull-down holds it low
  restoreDefaults();
  Serial.begin(115200);
  while (!Serial) {
    // Leonardo-class boards: wait for the USB CDC port
  }
  EICRA = (uint8_t)((EICRA & ~(_BV(ISC01) | _BV(ISC00))) | _BV(ISC01) | _BV(ISC00));  // INT0 rising
  EIFR = _BV(INTF0);
  EIMSK |= _BV(INT0);
  lastLineMs = millis();
  sendEvent(PSTR("READY"), PROTOCOL_VERSION, true);
}

static void serviceWatchdog() {
  if (state == STATE_ARMED && millis() - lastLineMs > WATCHDOG_MS) {
    disarm();
    sendEvent(PSTR("WATCHDOG"), 0, false);
  }
}

static void serviceSerial() {
  while (Serial.available() > 0) {
    char c = (char)Serial.read();
    if (c == '\n') {
      if (lineOverflow) {
        lastLineMs = millis();
        rejectLine(ERR_SYNTAX);
      } else {
        lineBuf[lineLen] = '\0';
        handleLine(lineBuf, lineLen);
      }
      lineLen = 0;
      lineOverflow = false;
    } else if (lineLen >= MAX_LINE - 1) {  // room for '\n' within MAX_LINE
      lineOverflow = true;
    } else {
      lineBuf[lineLen++] = c;
    }
  }
}

void loop() {
  servicePulses(false);
  serviceSerial();
  serviceWatchdog();
}
