// libFuzzer target: the streaming OBJ reader (and the MTL files an OBJ may name: "mtllib
// input.obj" makes the reader parse the input itself as MTL too).
#include "tests/fuzz/fuzz_model_reader.h"
#include "tests/fuzz/fuzz_quiet.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  raystack::fuzz::ReadModelFromBytes(data, size, false);
  return 0;
}
