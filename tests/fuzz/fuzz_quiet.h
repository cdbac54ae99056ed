#pragma once
// Every fuzz target includes this once: warnings about hostile input are expected by the
// million, and printing them would make the fuzzer measure the terminal.

#include "common/base/log.h"

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  raystack::SetLogLevel(raystack::LogLevel::kSilent);
  return 0;
}
