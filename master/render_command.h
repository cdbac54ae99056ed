#pragma once
// `raystack render SCENE.json [options]`: load the scene and its store, render every camera in
// turn with one engine (caches stay warm between frames), write each frame's EXR (and a PNG
// quick-look), print the statistics.

namespace raystack::master {

int RenderCommand(int argc, char** argv);

}  // namespace raystack::master
