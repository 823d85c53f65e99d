// Runs trigger_box.ino on a PC. Script on stdin, one step per line:
//   L <text>   the host sends "<text>\n"        R <hex>   the host sends raw bytes
//   S          a rising edge on the sync input  T <ms>    time passes
// The firmware's serial output goes to stdout unchanged.
#include <stdlib.h>
#include <string.h>

#include <deque>
#include <string>

#include "Arduino.h"

void setup();
void loop();

unsigned long g_now_us = 0;
int g_pin_level[32];
HostSerial Serial;
static std::deque<char> g_rx;
static void (*g_isr)() = nullptr;

int HostSerial::available() { return (int)g_rx.size(); }
int HostSerial::read() {
  if (g_rx.empty()) return -1;
  char c = g_rx.front();
  g_rx.pop_front();
  return (unsigned char)c;
}
void attachInterrupt(int, void (*isr)(), int) { g_isr = isr; }

static void run_loop() {
  for (int i = 0; i < 4; ++i) {
    loop();
    g_now_us += 10;
  }
}

int main() {
  setvbuf(stdout, nullptr, _IONBF, 0);
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
      if (g_isr) g_isr();
    } else if (step[0] == 'T' && step[1] == ' ') {
      g_now_us += strtoul(step + 2, nullptr, 10) * 1000UL;
    }
    run_loop();
  }
  return 0;
}
