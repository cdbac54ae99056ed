// A job across hosts: three network namespaces on this machine act as hosts joined by a
// private bridge (deploy/netns-cluster.sh), and mpirun starts one rank in each through
// deploy/netns-rsh.sh, over TCP only. The images equal the one-process image byte for byte,
// in `loc` and `rem`, and the slaves' pixels and blocks really crossed the virtual network.
// Needs root (CAP_NET_ADMIN), as in CI; skipped, saying why, where namespaces cannot be made.

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>

#include "tests/prep/run_process.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;
using prep::testing::Slurp;

const std::string kDeploy = RAYSTACK_SOURCE_DIR "/deploy";

class MultiHost : public StoreDirFixture {
 protected:
  void SetUp() override {
    if (geteuid() != 0) GTEST_SKIP() << "network namespaces need root (CI runs as root)";
    MakeStore("spheres:30000");
    name_ = "rsmh" + std::to_string(getpid());
    const ProcessResult up =
        RunProcess({kDeploy + "/netns-cluster.sh", "up", name_, "3"}, dir_->path());
    if (up.exit_code != 0) GTEST_SKIP() << "cannot make network namespaces here: " << up.err;
    up_ = true;
    std::ofstream(dir_->File("hosts")) << up.out;
    std::ofstream(dir_->File("scene.json")) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 80, "height": 60 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "materials": { "default": { "type": "diffuse", "albedo": [0.7, 0.6, 0.5] } },
      "integrator": { "type": "path", "max_depth": 3, "spp": 2, "seed": 3 } })";
  }
  void TearDown() override {
    if (up_) RunProcess({kDeploy + "/netns-cluster.sh", "down", name_}, dir_->path());
  }

  std::vector<std::string> RenderArgs(const std::string& out, const std::string& blocks) const {
    return {kRaystackBinary, "render", dir_->File("scene.json"), "--threads", "1",
            "--cache-mb", "1", "--blocks", blocks, "--output", out, "--no-png", "-q"};
  }

  // Bytes host `index` received on its network interface so far.
  uint64_t ReceivedBytes(int index) const {
    const ProcessResult r = RunProcess({"/usr/bin/env", "ip", "netns", "exec", name_ + "-h" + std::to_string(index),
                                        "cat", "/sys/class/net/eth0/statistics/rx_bytes"},
                                       dir_->path());
    return r.exit_code == 0 ? std::stoull(r.out) : 0;
  }

  std::string name_;
  bool up_ = false;
};

TEST_F(MultiHost, ImagesAcrossHostsEqualTheOneProcessImage) {
  const ProcessResult one = RunProcess(RenderArgs(dir_->File("one.exr"), "loc"), dir_->path());
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const std::string expected = Slurp(dir_->File("one.exr"));
  ASSERT_FALSE(expected.empty());
  for (const std::string blocks : {"loc", "rem"}) {
    const uint64_t before = ReceivedBytes(0);
    std::vector<std::string> argv = {
        "/usr/bin/env", "RAYSTACK_NETNS=" + name_, "ip", "netns", "exec", name_ + "-h0",
        RAYSTACK_MPIRUN, "--allow-run-as-root", "--hostfile", dir_->File("hosts"), "-np", "3",
        "--mca", "plm_rsh_agent", kDeploy + "/netns-rsh.sh",
        // TCP over the namespaces' own interfaces only: no shared memory between "hosts".
        "--mca", "btl", "tcp,self", "--mca", "btl_tcp_if_include", "10.231.0.0/24",
        "--mca", "oob_tcp_if_include", "10.231.0.0/24"};
    const std::string out = dir_->File(blocks + ".exr");
    for (const std::string& a : RenderArgs(out, blocks)) argv.push_back(a);
    const ProcessResult r = RunProcess(argv, dir_->path());
    ASSERT_EQ(r.exit_code, 0) << blocks << ": " << r.err << r.out;
    EXPECT_TRUE(Slurp(out) == expected) << blocks << ": the image differs from one process's";
    // The master on host 0 received the slaves' pixels over the wire: 80x60 pixels x 2
    // samples of at least 16 bytes each.
    EXPECT_GT(ReceivedBytes(0) - before, 80u * 60u * 2u * 16u) << blocks;
  }
}

}  // namespace
}  // namespace raystack::testing
