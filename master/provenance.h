#pragma once
// What an image was rendered from, as text: the build (BuildId), the store (its path, made
// canonical, and the checksum of its index), the camera, the lights, the materials,
// the background and the integrator. Written into every EXR (checkpoints too) as its
// "raystack.provenance" attribute (image::ImageLayers::provenance) and compared by --resume,
// so that a checkpoint of another camera, scene or setting is refused rather than taken for
// this frame's: the image size and sample count alone let an edited scene resume into the old
// image. Floats with 9 digits: the same value, the same text.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "common/render/scene.h"

namespace raystack::master {

std::string Provenance(const render::Scene& scene, size_t camera);

// The checksum of a store's index (which holds every block's checksum): equal for two copies of
// a store, different for a store rebuilt from another model. None if the index is unreadable.
std::optional<uint64_t> StoreChecksum(const std::string& store);
// StoreChecksum as this process first read it (each later call gives that): the store a job
// renders is the one it opened, whose files stay open when a conversion replaces the store
// (raystack-prep swaps new files in), so its images are that store's. Found by an operator: a
// store converted again mid-job was recorded in the next frames' images, and --resume then
// finished a frame of the old model with the new one.
std::optional<uint64_t> StoreChecksumAtStart(const std::string& store);
// Says once if the store at `store` is no longer the one this process first read.
void WarnIfStoreReplaced(const std::string& store);
// A checksum of what a frame's samples depend on besides the store: every camera, the lights,
// the materials, the background and the integrator (not the store's path, which may differ
// between hosts).
uint64_t SceneChecksum(const render::Scene& scene);

}  // namespace raystack::master
