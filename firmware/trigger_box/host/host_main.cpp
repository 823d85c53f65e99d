// Runs trigger_box.ino on a PC. Script on stdin, one step per line:
//   L <text>   the host sends "<text>\n"        R <hex>   the host sends raw bytes
//   S          a rising edge on the sync input  T <ms>    time passes
//   E <us>     two sync edges <us> apart (the second while the first one's pulse may run)
// After each step the loop runs until any pulse in flight has finished. The firmware's serial
// output goes to stdout unchanged.
#include <stdlib.h>
#include <string.h>

#include <deque>
#include <string>

#include "Arduino.h"

void setup();
void loop();

unsigned long g_now_us = 0;
int g_pin_level[32];
uint8_t g_eeprom[1024];
uint8_t TCCR1A, TCCR1B, TIMSK1, TIFR1, EICRA, EIMSK, EIFR, PORTB;
uint16_t TCNT1, OCR1A;
HostSerial Serial;
static std::deque<char> g_rx;
static unsigned g_half_us = 0;  // Timer1 ticks at F_CPU / 8 are half microseconds

int HostSerial::available() { return (int)g_rx.size(); }
int HostSerial::read() {
  if (g_rx.empty()) return -1;
  char c = g_rx.front();
  g_rx.pop_front();
  return (unsigned char)c;
}

static bool timer_running() { return (TCCR1B & _BV(CS11)) != 0; }

// Let `ticks` Timer1 ticks (0.5 us) pass, running the compare-match interrupt when due.
static void advance_ticks(unsigned long ticks) {
  while (ticks) {
    unsigned long step = ticks;
    if (timer_running()) {
      unsigned long to_match = (unsigned long)OCR1A + 1 - TCNT1;
      if (step >= to_match) {
        step = to_match;
        TCNT1 = 0;
        if (TIMSK1 & _BV(OCIE1A)) TIMER1_COMPA_vect();
      } else {
        TCNT1 = (uint16_t)(TCNT1 + step);
      }
    }
    ticks -= step;
    g_half_us += step;
    g_now_us += g_half_us / 2;
    g_half_us %= 2;
  }
}

void delayMicroseconds(unsigned int us) { advance_ticks(2UL * us); }

static void edge() {
  if (EIMSK & _BV(INT0)) INT0_vect();
}

static void run_loop() {
  for (int i = 0; i < 4; ++i) {
    loop();
    advance_ticks(20);
  }
  while (timer_running()) {  // a pulse in flight: let it finish, the loop running meanwhile
    advance_ticks(20);
    loop();
  }
  for (int i = 0; i < 4; ++i) {
    loop();
    advance_ticks(20);
  }
}

int main() {
  setvbuf(stdout, nullptr, _IONBF, 0);
  memset(g_eeprom, 0xFF, sizeof g_eeprom);  // erased
  setup();
  char step[512];
  while (fgets(step, sizeof step, stdin)) {
    size_t n = strlen(step);
    if (n && step[n - 1] == '\n') step[--n] = '\0';
    if (step[0] == 'L' && step[1] == ' ') {
      for (size_t i = 2; i < n; ++i) g_rx.push_back(step[i]);
      g_rx.push_back('\n');
    } else if (step[0] == 'R' && step[1] == ' ') {
      for (size_t i = 2; i + 1 < n; i += 2) {
        char hex[3] = {step[i], step[i + 1], 0};
        g_rx.push_back((char)strtol(hex, nullptr, 16));
      }
    } else if (step[0] == 'S') {
      edge();
    } else if (step[0] == 'E' && step[1] == ' ') {
      edge();
      advance_ticks(2UL * strtoul(step + 2, nullptr, 10));
      edge();
    } else if (step[0] == 'T' && step[1] == ' ') {
      g_now_us += strtoul(step + 2, nullptr, 10) * 1000UL;
    }
    run_loop();
  }
  return 0;
}
