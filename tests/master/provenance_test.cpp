// What an image records of the scene that rendered it (master/provenance.h), which --resume
// compares: every change that can change the image changes the record, and a scene with
// thousands of lights or materials still gives a record of bounded size.

#include "master/provenance.h"

#include <gtest/gtest.h>

#include <string>

namespace raystack::master {
namespace {

render::Scene ManyLights(int lights) {
  render::Scene scene;
  scene.store = "no-such-store";
  scene.cameras.emplace_back();
  for (int i = 0; i < lights; ++i)
    scene.lights.push_back({{static_cast<float>(i), 1, 2}, {1, 1, 1}});
  return scene;
}

TEST(Provenance, ALargeSceneKeepsABoundedRecordThatStillTellsScenesApart) {
  render::Scene scene = ManyLights(5000);
  const std::string record = Provenance(scene, 0);
  EXPECT_LE(record.size(), (16u << 10) + 100);
  EXPECT_NE(record.find("bytes more; checksum of the whole"), std::string::npos);
  EXPECT_EQ(Provenance(scene, 0), record);  // the same scene, the same record
  scene.lights.back().intensity.x = 2;      // past the kept lines
  EXPECT_NE(Provenance(scene, 0), record);
  // A small scene's record is whole.
  EXPECT_EQ(Provenance(ManyLights(3), 0).find("checksum"), std::string::npos);
}

}  // namespace
}  // namespace raystack::master
