#!/usr/bin/env bash
# Compile the firmware for the Arduino Due's SAM3X8E (Cortex-M3, Thumb-2) with Debian's
# arm-none-eabi toolchain: protocol.c as plain C, and the sketch as the Arduino IDE would
# (C++ with the Arduino API included first; here its declarations, target/arduino_api.h).
# Warnings are errors. Prints the object sizes. Nothing is linked: the Arduino core is not
# installed here, so this checks that the code compiles for the target, not that it runs.
# Usage: firmware/arduino_due/target/check_cross_compile.sh [OUT_DIR]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
src="$here/.."
out="${1:-$(mktemp -d)}"
mkdir -p "$out"
flags=(-mcpu=cortex-m3 -mthumb -Os -ffunction-sections -fdata-sections -Wall -Wextra -Werror
       -I"$src")
arm-none-eabi-gcc "${flags[@]}" -std=gnu11 -c "$src/protocol.c" -o "$out/protocol.o"
arm-none-eabi-g++ "${flags[@]}" -std=gnu++11 -fno-exceptions -fno-rtti -x c++ \
  -include "$here/arduino_api.h" -c "$src/arduino_due.ino" -o "$out/arduino_due.o"
arm-none-eabi-size "$out/protocol.o" "$out/arduino_due.o"
