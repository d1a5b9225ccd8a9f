// The fuzz targets' property check: a violated property stops the run where it happened (a
// trap, so libFuzzer and the smoke driver both report the input), also in release builds
// where assert() is compiled out.
#pragma once

#define REQUIRE(cond)                \
  do {                               \
    if (!(cond)) __builtin_trap();   \
  } while (0)
