#pragma once
// For the command-line tests of `raystack render`: a temporary folder holding a store that
// the real raystack-prep generated in it (`store/`), where scene files and outputs go too.

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "common/base/temp_dir.h"
#include "tests/prep/run_process.h"
#include "tests/support/test_dir.h"

namespace raystack::testing {

inline const std::string kRaystackBinary = RAYSTACK_BINARY_DIR "/master/raystack";

class StoreDirFixture : public ::testing::Test {
 protected:
  // Generates `spec` (raystack-prep --generate) into dir_/store, with blocks of ~8 KB.
  void MakeStore(const std::string& spec) {
    dir_ = raystack::testing::MakeTestDir();
    ASSERT_TRUE(dir_);
    const prep::testing::ProcessResult prep = prep::testing::RunProcess(
        {prep::testing::kPrepBinary, "--generate", spec, "-o", dir_->File("store"),
         "--target-block-kb", "8", "-q"},
        dir_->path());
    ASSERT_EQ(prep.exit_code, 0) << prep.err;
  }

  std::unique_ptr<TempDir> dir_;
};

}  // namespace raystack::testing
