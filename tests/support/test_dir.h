#pragma once
// A test's temporary folder (removed with it), or null after failing the test with the
// reason. Callers ASSERT_TRUE on the result.

#include <gtest/gtest.h>

#include <memory>
#include <utility>

#include "common/base/temp_dir.h"

namespace raystack::testing {

inline std::unique_ptr<TempDir> MakeTestDir() {
  Expected<TempDir> dir = TempDir::Create();
  if (!dir.ok()) {
    ADD_FAILURE() << "cannot create a temporary folder: " << dir.status().message();
    return nullptr;
  }
  return std::make_unique<TempDir>(std::move(*dir));
}

}  // namespace raystack::testing
