// fpp-rig trigger box firmware: trigger protocol version 1 (docs/trigger-protocol.md).
//
// Board: Arduino Uno / Nano / Leonardo class (AVR, 16 MHz). Not compiled in CI; build with
//   arduino-cli compile --fqbn arduino:avr:uno firmware/trigger_box
//
// The host sends checksummed ASCII lines "<id> <COMMAND> [args]*HH\n"; the box answers
// "<id> OK [data]*HH\n" or "<id> ERR <code> <NAME> [text]*HH\n" and sends events "! <EVENT> ...".
// A request identical to the last executed one (same id, command and arguments) is answered
// from the reply cache and not executed again (a retried FIRE never fires twice). mock_devices/trigger_box.py emulates
// this firmware; keep the two in step.
//
// Pins: D8 pulse out (camera trigger), D2 sync in (INT0, rising edge), D13 LED (armed).

#include <Arduino.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const uint8_t PROTOCOL_VERSION = 1;
static const char FIRMWARE_ID[] = "fpp-trigger-box/1.0.0";

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

static const char *errorName(uint8_t code) {
  switch (code) {
    case ERR_UNKNOWN_COMMAND: return "UNKNOWN_COMMAND";
    case ERR_BAD_ARGUMENT: return "BAD_ARGUMENT";
    case ERR_NOT_ARMED: return "NOT_ARMED";
    case ERR_STATE: return "STATE";
    case ERR_VERSION: return "VERSION";
    case ERR_BAD_CHECKSUM: return "BAD_CHECKSUM";
    case ERR_SYNTAX: return "SYNTAX";
    default: return "NO_HELLO";
  }
}

enum BoxState { STATE_IDLE, STATE_ARMED, STATE_DONE };

// -- settings and state ----------------------------------------------------------------------
static unsigned long widthUs = DEFAULT_WIDTH_US;
static unsigned long delayUs = 0;
static bool activeHigh = true;
static BoxState state = STATE_IDLE;
static bool sourceExt = false;
static unsigned long armedCount = 0;
static unsigned long firedCount = 0;
static bool helloDone = false;

static char lastRequest[MAX_LINE + 1] = "";  // the last executed request line, as received
static char lastReply[MAX_LINE + 1] = "";    // its reply body, without "*HH"
static unsigned long lastLineMs = 0;

static char lineBuf[MAX_LINE + 2];
static uint8_t lineLen = 0;
static bool lineOverflow = false;

// Sync edges are time-stamped in the interrupt so the configured delay counts from the edge.
static volatile bool edgePending = false;
static volatile unsigned long edgeAtUs = 0;
static volatile unsigned long edgesMissed = 0;

static void syncIsr() {
  if (edgePending) {
    edgesMissed++;
    return;
  }
  edgeAtUs = micros();
  edgePending = true;
}

// -- output ----------------------------------------------------------------------------------
static uint8_t xorOf(const char *body) {
  uint8_t value = 0;
  for (const char *p = body; *p; ++p) value ^= (uint8_t)*p;
  return value;
}

static void sendLine(const char *body) {
  static const char HEX_DIGITS[] = "0123456789ABCDEF";
  uint8_t cs = xorOf(body);
  Serial.print(body);
  Serial.write('*');
  Serial.write(HEX_DIGITS[cs >> 4]);
  Serial.write(HEX_DIGITS[cs & 0x0F]);
  Serial.write('\n');
}

static void sendEvent(const char *name, long value, bool withValue) {
  char body[32];
  if (withValue) {
    snprintf(body, sizeof body, "! %s %ld", name, value);
  } else {
    snprintf(body, sizeof body, "! %s", name);
  }
  sendLine(body);
}

// Build the reply into lastReply (the cache) and send it.
static void replyOk(unsigned long id, const char *data) {
  if (data && *data) {
    snprintf(lastReply, sizeof lastReply, "%lu OK %s", id, data);
  } else {
    snprintf(lastReply, sizeof lastReply, "%lu OK", id);
  }
  sendLine(lastReply);
}

static void replyError(unsigned long id, uint8_t code, const char *text) {
  snprintf(lastReply, sizeof lastReply, "%lu ERR %u %s %s", id, code, errorName(code), text);
  sendLine(lastReply);
}

// Errors about unreadable requests use id 0 and are not cached.
static void rejectLine(uint8_t code) {
  char body[48];
  snprintf(body, sizeof body, "0 ERR %u %s request rejected", code, errorName(code));
  sendLine(body);
}

// -- pulses ----------------------------------------------------------------------------------
static void setOutput(bool active) {
  digitalWrite(PIN_PULSE, (active == activeHigh) ? HIGH : LOW);
}

static void waitMicros(unsigned long us) {
  while (us > 16000UL) {  // delayMicroseconds is exact only up to 16383 us
    delayMicroseconds(16000);
    us -= 16000UL;
  }
  if (us) delayMicroseconds((unsigned int)us);
}

// One exposure: (the delay is waited by the caller) active for widthUs, then idle. Emits
// "! PULSE <index>" and returns the index.
static unsigned long emitPulse() {
  setOutput(true);
  waitMicros(widthUs);
  setOutput(false);
  unsigned long index = firedCount++;
  sendEvent("PULSE", (long)index, true);
  if (firedCount >= armedCount) {
    state = STATE_DONE;
    digitalWrite(PIN_LED, LOW);
  }
  return index;
}

static void disarm() {
  state = STATE_IDLE;
  armedCount = 0;
  firedCount = 0;
  digitalWrite(PIN_LED, LOW);
}

static void restoreDefaults() {
  disarm();
  widthUs = DEFAULT_WIDTH_US;
  delayUs = 0;
  activeHigh = true;
  sourceExt = false;
  setOutput(false);
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

  bool known = !strcmp(command, "HELLO") || !strcmp(command, "PING") ||
               !strcmp(command, "CONFIG") || !strcmp(command, "ARM") ||
               !strcmp(command, "FIRE") || !strcmp(command, "STATUS") ||
               !strcmp(command, "RESET");
  if (!known) {
    replyError(id, ERR_UNKNOWN_COMMAND, command);
    return;
  }
  if (!helloDone && strcmp(command, "HELLO") && strcmp(command, "PING")) {
    replyError(id, ERR_NO_HELLO, "send HELLO first");
    return;
  }

  if (!strcmp(command, "HELLO")) {
    if (nargs != 1 || !parseUnsigned(args[0], 0, 255, &a)) {
      replyError(id, ERR_BAD_ARGUMENT, "HELLO takes one version");
    } else if (a != PROTOCOL_VERSION) {
      snprintf(data, sizeof data, "box speaks %u", PROTOCOL_VERSION);
      replyError(id, ERR_VERSION, data);
    } else {
      helloDone = true;
      snprintf(data, sizeof data, "%u %s", PROTOCOL_VERSION, FIRMWARE_ID);
      replyOk(id, data);
    }
  } else if (!strcmp(command, "PING")) {
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, "PING takes no argument");
    } else {
      replyOk(id, "");
    }
  } else if (!strcmp(command, "CONFIG")) {
    bool positive = nargs == 3 && !strcmp(args[2], "POS");
    bool negative = nargs == 3 && !strcmp(args[2], "NEG");
    if (nargs != 3 || !parseUnsigned(args[0], 1, MAX_WIDTH_US, &a) ||
        !parseUnsigned(args[1], 0, MAX_DELAY_US, &b) || !(positive || negative)) {
      replyError(id, ERR_BAD_ARGUMENT, "CONFIG takes width_us delay_us POS or NEG");
    } else if (state == STATE_ARMED) {
      replyError(id, ERR_STATE, "armed RESET first");
    } else {
      widthUs = a;
      delayUs = b;
      activeHigh = positive;
      setOutput(false);
      snprintf(data, sizeof data, "%lu %lu %s", widthUs, delayUs, activeHigh ? "POS" : "NEG");
      replyOk(id, data);
    }
  } else if (!strcmp(command, "ARM")) {
    bool ext = nargs == 2 && !strcmp(args[1], "EXT");
    bool sw = nargs == 1 || (nargs == 2 && !strcmp(args[1], "SW"));
    if (nargs < 1 || nargs > 2 || !parseUnsigned(args[0], 1, MAX_ARM, &a) || !(ext || sw)) {
      replyError(id, ERR_BAD_ARGUMENT, "ARM takes count SW or EXT");
    } else if (state == STATE_ARMED) {
      replyError(id, ERR_STATE, "already armed RESET first");
    } else {
      noInterrupts();
      edgePending = false;  // an edge from before ARM does not count
      interrupts();
      state = STATE_ARMED;
      sourceExt = ext;
      armedCount = a;
      firedCount = 0;
      digitalWrite(PIN_LED, HIGH);
      snprintf(data, sizeof data, "%lu %s", armedCount, sourceExt ? "EXT" : "SW");
      replyOk(id, data);
    }
  } else if (!strcmp(command, "FIRE")) {
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, "FIRE takes no argument");
    } else if (state != STATE_ARMED) {
      replyError(id, ERR_NOT_ARMED, "ARM first");
    } else if (sourceExt) {
      replyError(id, ERR_STATE, "armed for EXT sync");
    } else {
      waitMicros(delayUs);
      unsigned long index = emitPulse();
      snprintf(data, sizeof data, "%lu", index);
      replyOk(id, data);
      if (state == STATE_DONE) sendEvent("DONE", (long)armedCount, true);
    }
  } else if (!strcmp(command, "STATUS")) {
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, "STATUS takes no argument");
    } else {
      const char *name = state == STATE_ARMED ? "ARMED" : (state == STATE_DONE ? "DONE" : "IDLE");
      snprintf(data, sizeof data,
               "state=%s armed=%lu fired=%lu width=%lu delay=%lu polarity=%s source=%s", name,
               armedCount, firedCount, widthUs, delayUs, activeHigh ? "POS" : "NEG",
               sourceExt ? "EXT" : "SW");
      replyOk(id, data);
    }
  } else {  // RESET
    if (nargs != 0) {
      replyError(id, ERR_BAD_ARGUMENT, "RESET takes no argument");
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
  pinMode(PIN_PULSE, OUTPUT);
  pinMode(PIN_LED, OUTPUT);
  pinMode(PIN_SYNC, INPUT);
  restoreDefaults();
  Serial.begin(115200);
  while (!Serial) {
    // Leonardo-class boards: wait for the USB CDC port
  }
  attachInterrupt(digitalPinToInterrupt(PIN_SYNC), syncIsr, RISING);
  lastLineMs = millis();
  sendEvent("READY", PROTOCOL_VERSION, true);
}

static void serviceSyncEdge() {
  if (!edgePending) return;
  noInterrupts();
  unsigned long at = edgeAtUs;
  edgePending = false;
  interrupts();
  if (state != STATE_ARMED || !sourceExt) return;  // not armed for sync: ignored
  unsigned long elapsed = micros() - at;
  if (elapsed < delayUs) waitMicros(delayUs - elapsed);
  emitPulse();
  if (state == STATE_DONE) sendEvent("DONE", (long)armedCount, true);
}

static void serviceWatchdog() {
  if (state == STATE_ARMED && millis() - lastLineMs > WATCHDOG_MS) {
    disarm();
    sendEvent("WATCHDOG", 0, false);
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
    serviceSyncEdge();  // keep sync latency low while a long line arrives
  }
}

void loop() {
  serviceSyncEdge();
  serviceSerial();
  serviceWatchdog();
}
