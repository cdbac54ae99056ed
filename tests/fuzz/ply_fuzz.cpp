// libFuzzer target: the streaming PLY reader (ascii and both binary byte orders).
#include "tests/fuzz/fuzz_model_reader.h"
#include "tests/fuzz/fuzz_quiet.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  raystack::fuzz::ReadModelFromBytes(data, size, true);
  return 0;
}
