#include "master/provenance.h"

#include <atomic>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>

#include "common/base/build_id.h"
#include "common/base/log.h"
#include "common/store/block_codec.h"
#include "common/store/format.h"

namespace raystack::master {
namespace {

// The store as a path that does not depend on how it was written ("store", "./store", an
// absolute path), and its contents: the checksum of index.bin's body, which holds every
// block's checksum. So a store rebuilt in place is another store, and the same store named
// differently is not.
std::string StoreIdentity(const std::string& store) {
  std::error_code ec;
  const std::filesystem::path canonical = std::filesystem::weakly_canonical(store, ec);
  std::string text = ec ? store : canonical.string();
  if (const std::optional<uint64_t> sum = StoreChecksumAtStart(store))
    text += StrFormat(" index %016llx", static_cast<unsigned long long>(*sum));
  else
    text += " (index unreadable)";
  return text;
}

// The scene's part of the record: camera `camera`, the lights, the materials, the background
// and the integrator.
std::string SceneRecord(const render::Scene& scene, size_t camera) {
  auto vec = [](const Vec3f& v) {
    return StrFormat("%.9g %.9g %.9g", double{v.x}, double{v.y}, double{v.z});
  };
  auto material = [&](const render::Material& m) {
    return StrFormat("type %d albedo %s ior %.9g emission %s", static_cast<int>(m.type),
                     vec(m.albedo).c_str(), double{m.ior}, vec(m.emission).c_str());
  };
  const render::CameraDesc& c = scene.cameras[camera];
  std::string text = StrFormat("camera: position %s look_at %s up %s fov_y_deg %.9g size %dx%d\n",
                               vec(c.position).c_str(), vec(c.look_at).c_str(), vec(c.up).c_str(),
                               double{c.fov_y_deg}, c.width, c.height);
  for (const render::PointLight& l : scene.lights)
    text += "light: position " + vec(l.position) + " intensity " + vec(l.intensity) + "\n";
  text += "material default: " + material(scene.default_material) + "\n";
  for (const auto& [name, m] : scene.overrides) text += "material " + name + ": " + material(m) + "\n";
  text += "background " + vec(scene.background) + "\n";
  const render::IntegratorDesc& i = scene.integrator;
  text += StrFormat("integrator type %d max_depth %d spp %d seed %llu\n", static_cast<int>(i.type),
                    i.max_depth, i.spp, static_cast<unsigned long long>(i.seed));
  // The frame's index matters only then (records without it stay as they were).
  if (i.animated_seed) text += StrFormat("animated_seed frame %zu\n", camera);
  return text;
}

}  // namespace

std::optional<uint64_t> StoreChecksum(const std::string& store) {
  store::FileHeader header{};
  std::ifstream index(store + "/" + store::kIndexFile, std::ios::binary);
  if (!index.read(reinterpret_cast<char*>(&header), sizeof header)) return std::nullopt;
  uint64_t sum = header.body_checksum;
  // With lights.bin's: a copy converted before it existed has the same index, but its path
  // tracing finds emitters another way (another image, as noisy), so it is another store.
  std::ifstream lights(store + "/" + store::kLightsFile, std::ios::binary);
  if (lights.read(reinterpret_cast<char*>(&header), sizeof header))
    sum ^= (header.body_checksum + 1) * 0x9e3779b97f4a7c15ull;
  return sum;
}

std::optional<uint64_t> StoreChecksumAtStart(const std::string& store) {
  static std::mutex mu;
  static std::map<std::string, std::optional<uint64_t>> first;
  std::lock_guard lock(mu);
  auto [it, inserted] = first.try_emplace(store);
  if (inserted) it->second = StoreChecksum(store);
  return it->second;
}

void WarnIfStoreReplaced(const std::string& store) {
  static std::atomic<bool> said{false};
  if (said || StoreChecksum(store) == StoreChecksumAtStart(store)) return;
  if (said.exchange(true)) return;
  LOG_WARNING("render", "%s: the store was replaced (converted again?) after this job opened it; "
              "the job goes on rendering the store it opened (its files stay open), and its "
              "images say so", store.c_str());
}

uint64_t SceneChecksum(const render::Scene& scene) {
  std::string text;
  for (size_t c = 0; c < scene.cameras.size(); ++c) text += SceneRecord(scene, c);
  return store::Checksum({reinterpret_cast<const uint8_t*>(text.data()), text.size()});
}

std::string Provenance(const render::Scene& scene, size_t camera) {
  // (Not the frame's index, unless animated_seed: a camera repeated gives the same image.)
  std::string text = StrFormat("raystack render 1\nbuild %s\nstore %s\n", BuildId(),
                               StoreIdentity(scene.store).c_str()) +
                     SceneRecord(scene, camera);
  // The record rides in every image's header: a scene of thousands of lights or materials
  // keeps its first lines and a checksum of the whole, which tells scenes apart as well.
  constexpr size_t kMaxBytes = 16 << 10;
  if (text.size() > kMaxBytes) {
    const uint64_t sum = store::Checksum(
        {reinterpret_cast<const uint8_t*>(text.data()), text.size()});
    const size_t cut = text.rfind('\n', kMaxBytes) + 1;
    text = text.substr(0, cut) + StrFormat("... %zu bytes more; checksum of the whole %016llx\n",
                                           text.size() - cut, static_cast<unsigned long long>(sum));
  }
  return text;
}

}  // namespace raystack::master
