// Declarations of the part of the Arduino (SAM core) API that arduino_due.ino uses, so the sketch
// can be compiled for the Due's Cortex-M3 with arm-none-eabi-g++ where the Arduino core is not
// installed (check_cross_compile.sh). Declarations only: nothing here is linked or run. The
// signatures follow the Arduino SAM core 1.6.x (cores/arduino/wiring_*.h, USB/USBAPI.h).
#pragma once
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <stddef.h>

#define HIGH 0x1
#define LOW 0x0
#define INPUT 0x0
#define OUTPUT 0x1
#define INPUT_PULLUP 0x2
#define CHANGE 2

void pinMode(uint32_t pin, uint32_t mode);
void digitalWrite(uint32_t pin, uint32_t val);
int digitalRead(uint32_t pin);
void analogWrite(uint32_t pin, uint32_t val);
uint32_t millis(void);
uint32_t micros(void);
void attachInterrupt(uint32_t pin, void (*callback)(void), uint32_t mode);
#define digitalPinToInterrupt(p) (p)
#define interrupts() __asm__ volatile("cpsie i")
#define noInterrupts() __asm__ volatile("cpsid i")

#ifdef __cplusplus
template <class T, class L> auto min(const T& a, const L& b) -> decltype((b < a) ? b : a) {
  return (b < a) ? b : a;
}

class Serial_ {  // the Due's native USB port (SerialUSB)
 public:
  void begin(uint32_t baud);
  int available(void);
  int read(void);
  size_t write(const uint8_t* buffer, size_t size);
};
extern Serial_ SerialUSB;
#endif
