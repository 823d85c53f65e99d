// Host (PC) stand-in for the few Arduino APIs trigger_box.ino uses, so the firmware can be
// compiled with g++ and run against scripted input (tests/test_trigger_box_firmware.py).
// The Arduino build ignores this folder (only the sketch root and src/ are compiled).
#pragma once

#include <stdint.h>
#include <stdio.h>

#define HIGH 1
#define LOW 0
#define INPUT 0
#define OUTPUT 1
#define RISING 3

extern unsigned long g_now_us;
extern int g_pin_level[32];

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
inline void delayMicroseconds(unsigned int us) { g_now_us += us; }
inline void pinMode(uint8_t, uint8_t) {}
inline void digitalWrite(uint8_t pin, uint8_t level) { g_pin_level[pin & 31] = level; }
inline void noInterrupts() {}
inline void interrupts() {}
inline int digitalPinToInterrupt(uint8_t pin) { return pin == 2 ? 0 : -1; }
void attachInterrupt(int irq, void (*isr)(), int mode);
