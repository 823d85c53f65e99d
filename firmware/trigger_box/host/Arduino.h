// Host (PC) stand-in for the Arduino and AVR APIs trigger_box.ino uses, so the firmware can be
// compiled with g++ and run against scripted input (tests/test_trigger_box_firmware.py).
// Timer1 (CTC mode, F_CPU / 8) and INT0 are emulated by host_main.cpp: time advances in steps and
// the compare-match interrupt runs when the counter reaches OCR1A. Flash strings are plain
// strings here; "%S" (avr-libc: a string in flash) is rewritten to "%s" before formatting.
// The Arduino build ignores this folder (only the sketch root and src/ are compiled).
#pragma once

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define HIGH 1
#define LOW 0
#define INPUT 0
#define OUTPUT 1
#define RISING 3

#define PROGMEM
#define PGM_P const char *
#define PSTR(s) (s)
#define F(s) (s)
#define _BV(bit) (1U << (bit))

// Timer1, INT0 and port B registers (bit numbers as on the ATmega328P)
extern uint8_t TCCR1A, TCCR1B, TIMSK1, TIFR1, EICRA, EIMSK, EIFR, PORTB;
extern uint16_t TCNT1, OCR1A;
#define WGM12 3
#define CS11 1
#define OCIE1A 1
#define OCF1A 1
#define ISC01 1
#define ISC00 0
#define INT0 0
#define INTF0 0
#define PB0 0
#define ISR(vector) void vector()
void TIMER1_COMPA_vect();
void INT0_vect();

extern unsigned long g_now_us;
extern int g_pin_level[32];
extern uint8_t g_eeprom[1024];

class HostSerial {
 public:
  void begin(unsigned long) {}
  explicit operator bool() const { return true; }
  int available();
  int read();
  size_t print(const char *text) { return fputs(text, stdout) >= 0 ? 1 : 0; }
  size_t write(char c) { return fputc(c, stdout) != EOF ? 1 : 0; }
};
extern HostSerial Serial;

inline unsigned long millis() { return g_now_us / 1000UL; }
inline unsigned long micros() { return g_now_us; }
void delayMicroseconds(unsigned int us);  // advances time, running due timer interrupts
inline void pinMode(uint8_t, uint8_t) {}
inline void digitalWrite(uint8_t pin, uint8_t level) { g_pin_level[pin & 31] = level; }
inline void noInterrupts() {}
inline void interrupts() {}

inline uint8_t eeprom_read_byte(const uint8_t *address) { return g_eeprom[(uintptr_t)address & 1023]; }
inline void eeprom_update_byte(uint8_t *address, uint8_t value) { g_eeprom[(uintptr_t)address & 1023] = value; }

inline int strcmp_P(const char *a, const char *b) { return strcmp(a, b); }
inline int snprintf_P(char *out, size_t size, const char *format, ...) {
  char host_format[128];
  size_t n = 0;
  for (const char *p = format; *p && n + 2 < sizeof host_format; ++p) {
    host_format[n++] = *p;
    if (p[0] == '%' && p[1] == 'S') {
      host_format[n++] = 's';
      ++p;
    }
  }
  host_format[n] = '\0';
  va_list args;
  va_start(args, format);
  int written = vsnprintf(out, size, host_format, args);
  va_end(args);
  return written;
}
